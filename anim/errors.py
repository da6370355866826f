"""The one error type for bad input: names the file, the key path and the problem."""


def one_line(text) -> str:
    """text with control characters (newlines, carriage returns, bidi
    overrides...) escaped, so that an error stays one printable line
    whatever a scene file's keys and values contain."""
    text = str(text)
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class SceneError(Exception):
    """Bad scene input. str() is one line: `file: key.path: problem`."""

    def __init__(self, file, key, problem):
        self.file, self.key, self.problem = one_line(file), one_line(key), one_line(problem)
        where = f"{self.file}: {self.key}: " if self.key else f"{self.file}: "
        super().__init__(where + self.problem)
