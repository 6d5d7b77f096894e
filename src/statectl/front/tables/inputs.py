"""Reading an input file without trusting what the path names.

A device file, cell file, run config or trace named ``x.yaml`` may be a FIFO (whose
``open`` waits for a writer and whose read never ends) or a device such as
``/dev/zero`` (endless). Every reader of input files goes through :func:`read_input`,
which refuses anything but a regular file before reading a byte, with an
``OSError`` whose ``strerror`` says so, so each caller's existing handler reports it.
"""

from __future__ import annotations

import errno
import os
import stat


class NotRegularFile(OSError):
    """The path names a FIFO, a device or a socket: nothing is read from it."""


def read_input(path: str | os.PathLike[str]) -> bytes:
    """The bytes of the regular file at ``path``; ``OSError`` for anything else."""
    # O_NONBLOCK: opening a FIFO for reading must not wait for a writer
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, "it is a directory, not a file", str(path))
        if not stat.S_ISREG(mode):
            raise NotRegularFile(
                errno.EINVAL,
                "not a regular file (a FIFO, device or socket); name a file",
                str(path),
            )
        os.set_blocking(fd, True)
        with os.fdopen(os.dup(fd), "rb") as fh:
            return fh.read()
    finally:
        os.close(fd)


def read_input_text(path: str | os.PathLike[str]) -> str:
    """:func:`read_input` decoded as UTF-8 (``UnicodeDecodeError`` if it is not)."""
    return read_input(path).decode("utf-8")
