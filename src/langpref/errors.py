"""The one exception type the CLI turns into a clean one-line message."""


class LangprefError(Exception):
    """A user-facing error: bad input, a corrupt or mismatched file. Its message is one line saying what to do."""
