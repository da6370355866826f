"""The one error type for bad input: names the file, the key path and the problem."""


class SceneError(Exception):
    """Bad scene input. str() is one line: `file: key.path: problem`."""

    def __init__(self, file, key, problem):
        self.file, self.key, self.problem = str(file), key, problem
        where = f"{self.file}: {key}: " if key else f"{self.file}: "
        super().__init__(where + problem)
