"""Hearing numba compile gndreplay's kernels: a cold disk cache (the first run after installing) compiles
them, which takes seconds the user should be told about."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["CompileListener"]


class CompileListener:
    """While active, calls ``callback(name)`` for each gndreplay numba kernel compiled (a disk-cache miss),
    named ``module.function`` (numba's own helpers compiled along are not reported)."""

    def __init__(self, callback: Callable[[str], None]) -> None:
        from numba.core import event

        class Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
                func = getattr(disp, "py_func", None)
                module = str(getattr(func, "__module__", ""))
                if module.startswith("gndreplay."):
                    callback(f"{module.rsplit('.', 1)[-1]}.{getattr(func, '__qualname__', '?')}")

            def on_end(self, ev: Any) -> None:
                pass

        self._event = event
        self._listener = Listener()

    def __enter__(self) -> None:
        self._event.register("numba:compile", self._listener)

    def __exit__(self, *exc: object) -> None:
        self._event.unregister("numba:compile", self._listener)
