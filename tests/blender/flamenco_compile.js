// Compile a Flamenco job type outside Flamenco: run its compileJob with the few globals the
// Manager provides (author.Task / author.Command, print) recorded as plain data, and print the
// tasks as JSON. The job file and its settings (JSON) are the arguments. This checks what our
// job type emits; the commands are then run against the real CLI by the pytest that calls it.
const fs = require("fs");
const vm = require("vm");

const [jobFile, settingsJson] = process.argv.slice(2);
const tasks = [];
const author = {
    Task(name, type) {
        const t = { name, type, commands: [], deps: [] };
        t.addCommand = (c) => t.commands.push(c);
        t.addDependency = (other) => t.deps.push(other.name);
        return t;
    },
    Command(name, params) { return { name, params }; },
};
const context = { author, print: () => {}, console };
vm.createContext(context);
vm.runInContext(fs.readFileSync(jobFile, "utf8") + "\n;this.JOB_TYPE = JOB_TYPE;", context);
const job = { settings: JSON.parse(settingsJson), addTask: (t) => tasks.push(t) };
context.compileJob(job);
const keys = context.JOB_TYPE.settings.map((s) => s.key);
process.stdout.write(JSON.stringify({ keys, tasks: tasks.map(({ name, type, commands, deps }) =>
    ({ name, type, commands, deps })) }));
