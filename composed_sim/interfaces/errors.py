"""The one error an interface package's build gives a user."""


class InterfaceError(Exception):
    """An interface package that cannot be read or built, or a missing tool: the message says
    which file (and line), or which wheel or tool, and what to do."""
