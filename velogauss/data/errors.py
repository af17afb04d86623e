"""The one exception every data loader raises for bad data (spec/conventions.md, "Bad input")."""


class DataError(ValueError):
    """Bad dataset content, reported once, before any training starts.

    The message names where the problem is and what is wrong with it:
    `"<file>: <field>: <what>"` for a file's content (`field` is the JSON key, PLY property
    or the image path) and `"<argument>: <what>"` for a bad loader argument (`file` None).
    `file` and `field` are kept as attributes so a caller can report them separately.
    """

    def __init__(self, file, field, message):
        self.file = None if file is None else str(file)
        self.field = field
        prefix = f"{field}: " if self.file is None else f"{self.file}: {field}: "
        super().__init__(prefix + message)
