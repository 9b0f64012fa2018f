"""Progress of long calls: herdfit reports ``start(what, total)``, ``inc(n)``, ``message(text)``
and ``finish()``; :func:`resolve` turns the ``progress=`` argument into such an object."""

from __future__ import annotations

from typing import Any, Callable, Optional


class Tqdm:
    """A tqdm bar per stage (``tqdm.auto``: a widget in Jupyter, text elsewhere)."""

    def __init__(self) -> None:
        from tqdm.auto import tqdm

        self._tqdm = tqdm
        self._bar: Any = None

    def start(self, what: str, total: int) -> None:
        self.finish()
        self._bar = self._tqdm(total=total or None, desc=what, leave=False)

    def inc(self, n: int) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def message(self, text: str) -> None:
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)

    def finish(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


class Callback:
    """Calls ``fn(stage, done, total, message)`` after every unit of work."""

    def __init__(self, fn: Callable[[str, int, int, str], Any]) -> None:
        self._fn = fn
        self._stage, self._done, self._total, self._msg = "", 0, 0, ""

    def start(self, what: str, total: int) -> None:
        self._stage, self._done, self._total, self._msg = what, 0, total, ""

    def inc(self, n: int) -> None:
        self._done += n
        self._fn(self._stage, self._done, self._total, self._msg)

    def message(self, text: str) -> None:
        self._msg = text

    def finish(self) -> None:
        pass


def resolve(progress: Any) -> Optional[Any]:
    """``True`` (default): tqdm when installed, else nothing; ``False``/``None``: nothing; a
    callable: :class:`Callback`; an object with ``start``/``inc``/``finish``: itself."""
    if progress is None or progress is False:
        return None
    if progress is True:
        try:
            return Tqdm()
        except ImportError:
            return None
    if hasattr(progress, "inc"):
        return progress
    if callable(progress):
        return Callback(progress)
    raise TypeError("progress must be True, False, a callable or an object with inc()")
