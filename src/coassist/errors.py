"""The base class of coassist's own exceptions.

Every exception class coassist defines derives from :class:`CoassistError` *and* from
the built-in it has always been (``ValueError`` for bad input, ``RuntimeError`` for a
failed computation, ``ConnectionError`` for a lost robot link, ``KeyError`` for an
unknown name), so ``except CoassistError`` catches everything coassist raises on
purpose while code that catches the built-in keeps working.
"""

from __future__ import annotations

__all__ = ["CoassistError"]


class CoassistError(Exception):
    """Raised by coassist on purpose (always together with a built-in base, see the module)."""
