"""Where outputs go. Every file stiff writes goes through `stiff_file_write` (atomic replace of
regular files, write-through to devices and pipes, symbolic links followed, read-only and
non-regular files refused). Inside a command (`transaction()`), outputs are staged in a private
folder and committed only when the whole command has succeeded, after checking that none of
them is a file the command read (same device and inode, whatever the names)."""
from __future__ import annotations

import contextlib
import io
import os
import shutil
import stat
import sys
import tempfile

from . import _capi as _c
from .errors import StiffIOError

_current: "Transaction | None" = None


def _identity(path: str):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def write_now(path, data: bytes) -> None:
    """Write bytes through the library's writer (the one set of rules for every output)."""
    _c.check(_c.lib.stiff_file_write(_c.encode(os.fspath(path)), data, len(data)))


def note_input(path) -> None:
    """A file the running command reads: refused as an output of the same command."""
    if _current is not None and path is not None:
        _current.inputs.append(os.fspath(path))


def target(path) -> str:
    """The path a writer should write `path` to: itself, or its staged copy in a command."""
    return _current.stage(path) if _current is not None else os.fspath(path)


def written(path) -> str:
    """Where an output this command already wrote can be read back: its staged copy inside a
    command (it is committed only at the end), else the path itself."""
    if _current is not None and os.fspath(path) in _current.outputs:
        return _current.outputs[os.fspath(path)]
    return os.fspath(path)


def write_bytes(path, data: bytes) -> None:
    if _current is None:
        write_now(path, data)
    else:
        with open(_current.stage(path), "wb") as f:
            f.write(data)


def write_text(path, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def save_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure, rendered in memory and written like every other output."""
    name = os.fspath(path)
    fmt = kwargs.pop("format", None) or (os.path.splitext(name)[1][1:].lower() or "png")
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, **kwargs)
    write_bytes(name, buf.getvalue())


class Transaction:
    def __init__(self):
        self.outputs: dict[str, str] = {}
        self.inputs: list[str] = []
        self._dir: str | None = None

    def check(self, path: str) -> None:
        """Refuse now what committing would refuse, before the work is done."""
        if path == "-":
            return
        if not path:
            raise StiffIOError("output path is empty", -4)
        real = os.path.realpath(path)
        if os.path.isdir(real):
            raise StiffIOError(f"{path}: is a directory", -4)
        parent = os.path.dirname(real) or "."
        if not os.path.isdir(parent):
            raise StiffIOError(f"{path}: cannot write there: the folder '{os.path.dirname(path) or '.'}' "
                               "does not exist", -4)
        if len(os.path.basename(real).encode()) > os.pathconf(parent, "PC_NAME_MAX"):
            raise StiffIOError(f"{path}: the file name is too long for this file system", -4)
        mine = _identity(real)
        if mine is not None:
            for i in self.inputs:
                if _identity(i) == mine:
                    raise StiffIOError(f"{path}: is an input of this command ({i}); write the "
                                       "output to another file", -4)

    def stage(self, path) -> str:
        path = os.fspath(path)
        if path in self.outputs:
            return self.outputs[path]
        self.check(path)
        if self._dir is None:
            self._dir = tempfile.mkdtemp(prefix="stiff-")
        # The staged name keeps the suffix: writers (matplotlib) choose the format by it.
        staged = os.path.join(self._dir, f"{len(self.outputs)}{os.path.splitext(path)[1]}")
        self.outputs[path] = staged
        return staged

    def public(self, message: str) -> str:
        """An error message with staged paths replaced by the outputs they stand for."""
        for final, staged in self.outputs.items():
            message = message.replace(staged, final)
        return message

    def commit(self) -> None:
        for final in self.outputs:
            self.check(final)
        sys.stdout.flush()
        for final, staged in self.outputs.items():
            if not os.path.exists(staged):  # declared, never written
                continue
            with open(staged, "rb") as f:
                write_now(final, f.read())

    def discard(self) -> None:
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None


@contextlib.contextmanager
def transaction():
    """Outputs written inside are committed when the block ends without an exception."""
    global _current
    t = Transaction()
    _current = t
    try:
        yield t
        _current = None
        t.commit()
    finally:
        _current = None
        t.discard()
