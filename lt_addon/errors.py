"""The one error type for input that cannot be baked, fitted or read: bad settings, a bundle of
a newer format. The message says what to change; the CLI prints it as one line and the panel's
operators report it. (The bpy layer raises the same class as ``BakeInputError``.)"""


class InputError(ValueError):
    """The object, settings or file cannot be used; the message says what to change."""
