"""Exceptions carrying the C ABI's status and message."""
from __future__ import annotations

import re


class StiffError(Exception):
    """Base of every error raised by stiff; `.status` is the C stiff_status code."""

    status = -99

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        if status is not None:
            self.status = status


class InvalidArgumentError(StiffError, ValueError):
    status = -1


class InvalidStateError(StiffError, RuntimeError):
    status = -2


class ParseError(StiffError, ValueError):
    """A malformed input file; `.path`, `.line` and `.column` locate the problem."""

    status = -3

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message, status)
        self.path, self.line, self.column = None, None, None
        body = message.split(": ", 1)[1] if ": " in message else message
        m = re.match(r"(.+?):(\d+)(?::(\d+))?: ", body)
        if m:
            self.path = m.group(1)
            self.line = int(m.group(2))
            self.column = int(m.group(3)) if m.group(3) else None
        else:
            m = re.match(r"(.+?): ", body)
            if m:
                self.path = m.group(1)


class StiffIOError(StiffError, OSError):
    status = -4


class BufferTooSmallError(StiffError):
    status = -5


class NumericalError(StiffError, ArithmeticError):
    status = -6


class CancelledError(StiffError):
    status = -7


class StiffMemoryError(StiffError, MemoryError):
    status = -8


class InternalError(StiffError):
    status = -99


_BY_STATUS = {
    -1: InvalidArgumentError,
    -2: InvalidStateError,
    -3: ParseError,
    -4: StiffIOError,
    -5: BufferTooSmallError,
    -6: NumericalError,
    -7: CancelledError,
    -8: StiffMemoryError,
    -99: InternalError,
}


def error_for(status: int, message: str) -> StiffError:
    return _BY_STATUS.get(status, StiffError)(message, status)
