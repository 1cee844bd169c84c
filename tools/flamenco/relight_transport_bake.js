// SPDX-License-Identifier: GPL-3.0-or-later
//
// Flamenco job type: a Relightable Textures transport bake on a render farm.
//
// One task per chunk of 16 light directions runs `relight bake-chunk` in Blender
// (`blender -b FILE --command relight bake-chunk FILE ... --chunk K`), writing the chunk
// into <out>/.relight_cache on shared storage; a final task, after all of them, runs
// `relight bake-textures` with the same arguments, which finds every chunk, bakes the
// indirect term, fits the model and writes the files. A failed or requeued chunk task is
// simply run again (a chunk already in the cache is not baked twice).
//
// Install: copy this file into the Flamenco Manager's `scripts/` folder and restart it.
// Workers need Blender with the Relightable Textures extension enabled, and must read the
// .blend and the output folder at the same paths. Not run on a Flamenco farm here: the
// commands it emits are tested against the real CLI (tests/blender/test_distributed.py).

const JOB_TYPE = {
    label: "Relightable Textures: transport bake",
    settings: [
        { key: "objects", type: "string", required: true,
          eval: "','.join(o.name for o in C.selected_objects if o.type == 'MESH')",
          description: "Mesh objects baked together, comma-separated" },
        { key: "preset", type: "string", default: "balanced",
          choices: ["draft", "balanced", "production"],
          description: "Starting values of the settings (as the panel's presets)" },
        { key: "directions", type: "string", default: "",
          description: "Sun directions, hemi:N[:P] (empty: the preset's)" },
        { key: "resolution", type: "int32", default: 0,
          description: "Texture side in texels (0: the preset's)" },
        { key: "force", type: "bool", default: false,
          description: "Replace an existing bake of these objects in the output folder" },
        { key: "output_dir", type: "string", subtype: "dir_path", required: true,
          visible: "submission", description: "The bake's output folder (shared storage)" },
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "Path of the .blend file to bake" },
    ]
};

const CHUNK_DIRECTIONS = 16;
// The presets' direction sets (operators/bakes/transport_presets.json).
const PRESET_DIRECTIONS = { draft: "hemi:400:1.5", balanced: "hemi:400:1.5", production: "hemi:2800:1.5" };
// The bake adds the set's directions under UNDER_DEG of elevation mirrored under the horizon
// (lt_addon/sphere/under_horizon.py, a wide sun's disc there); a scene Sun wider than twice
// that adds a few more, which the final task bakes itself.
const UNDER_DEG = 5.0;

// How many directions the bake has: those of `hemi:N[:P]` (or the preset's), and their band
// under UNDER_DEG mirrored (hemi:N:P puts direction i at sin(elevation) ((i + 0.5) / N)^P).
function directionCount(settings) {
    const spec = settings.directions || PRESET_DIRECTIONS[settings.preset || "balanced"];
    const m = /^hemi:(\d+)(?::([0-9.]+))?$/.exec(spec || "");
    if (!m) {
        throw `directions must be hemi:N[:P], got "${settings.directions}"`;
    }
    const n = parseInt(m[1], 10);
    const power = m[2] ? parseFloat(m[2]) : 1.0;
    const top = Math.sin(UNDER_DEG * Math.PI / 180);
    let under = 0;
    for (let i = 0; i < n; i++) {
        if (Math.pow((i + 0.5) / n, power) < top) {
            under++;
        }
    }
    return n + under;
}

// The arguments both commands share: the file, the objects, the settings, the folder.
function bakeArgs(settings) {
    const args = [settings.blendfile];
    for (const name of settings.objects.split(",")) {
        if (name.trim()) {
            args.push("--object", name.trim());
        }
    }
    args.push("--preset", settings.preset || "balanced");
    // A farm distributes Cycles calls: one per direction. (With the default ray-traced direct
    // light a workstation bakes the directions in seconds; the chunk tasks would go unused.)
    args.push("--direct", "cycles");
    if (settings.directions) {
        args.push("--directions", settings.directions);
    }
    if (settings.resolution) {
        args.push("--resolution", String(settings.resolution));
    }
    args.push("--out", settings.output_dir);
    return args;
}

function relightCommand(settings, verbArgs) {
    return author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: [],
        blendfile: settings.blendfile,
        args: ["--command", "relight"].concat(verbArgs),
    });
}

function compileJob(job) {
    const settings = job.settings;
    const n = Math.ceil(directionCount(settings) / CHUNK_DIRECTIONS);
    if (!(n >= 1)) {
        throw `no directions to bake (preset "${settings.preset}")`;
    }
    const chunkTasks = [];
    for (let k = 0; k < n; k++) {
        const task = author.Task(`relight-chunk-${k}`, "blender");
        task.addCommand(relightCommand(settings,
            ["bake-chunk"].concat(bakeArgs(settings), ["--chunk", String(k)])));
        job.addTask(task);
        chunkTasks.push(task);
    }
    const finish = author.Task("relight-fit-and-write", "blender");
    finish.addCommand(relightCommand(settings,
        ["bake-textures"].concat(bakeArgs(settings), settings.force ? ["--force"] : [])));
    for (const t of chunkTasks) {
        finish.addDependency(t);
    }
    job.addTask(finish);
}
