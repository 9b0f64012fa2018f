"""The exceptions herdfit raises. Each carries herdfit's one-line message."""

from __future__ import annotations

from typing import Optional

__all__ = ["HerdfitError", "ConfigError", "FileError"]


class HerdfitError(Exception):
    """Any error of herdfit (an impossible request, an internal failure)."""


class ConfigError(HerdfitError, ValueError):
    """A bad setting, named by its config key (``.key``; the keyword argument's name)."""

    def __init__(self, message: str, key: str = "") -> None:
        super().__init__(message)
        self.key = key


class FileError(HerdfitError, OSError):
    """A file that cannot be read or written, or holds bad values (``.filename``)."""

    def __init__(self, message: str, filename: Optional[str] = None) -> None:
        super().__init__(message)
        self.filename = None if filename is None else str(filename)

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
