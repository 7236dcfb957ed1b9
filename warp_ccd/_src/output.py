"""Output files: checking a destination early, and replacing it in one step.

Every file the library writes (USD stages, preview images) goes through here:

* :func:`check_output_path` checks a destination when the writer is created, before any
  simulation runs: a known extension, an existing folder, and a real probe that a file can be
  created there (permission bits alone say little, e.g. for root or on read-only mounts).
* :class:`PendingFile` is written as a hidden temporary file in the destination's folder and
  renamed over the destination only when complete (``os.replace``, atomic on one file system), so
  an interrupted run never leaves a partial file at the destination, and a file already there
  stays as it was until the new one is whole. :func:`commit_all` moves several into place
  together once every one of them is written, so that a run writing several files leaves all of
  them or none.

**Destinations that are not regular files.** A destination that exists and is not a regular file
(a FIFO, a character or block device, a socket) is refused with a ValueError naming it, at the
check and again just before the rename: replacing it would remove a device node or a pipe another
program reads. A **symbolic link** is written *through*: the file it points to is replaced (its
temporary file made in the target's folder) and the link stays a link, as ``open(path, "w")``
would do; a link whose target is not a regular file is refused as that target is.
"""

from __future__ import annotations

import os
import stat
import tempfile
import weakref

__all__ = ["PendingFile", "check_output_path", "commit_all", "prepare_text", "same_file"]


def check_output_path(path, extensions: tuple[str, ...], kind: str) -> tuple[str, str]:
    """Checks that a file of one of ``extensions`` can be written at ``path``, without writing it.

    Args:
        path: destination (str or path-like).
        extensions: accepted lower-case extensions with their dot, e.g. ``(".png", ".gif")``.
        kind: what the file is, for messages (``"USD"``, ``"preview"``).

    Returns:
        ``(absolute path, lower-case extension)``.

    Raises:
        ValueError: one line naming the path and the problem: an unknown extension, a missing
            folder, a folder where the file should be, a FIFO, device or socket there (not a
            regular file), a read-only file, or a folder in which no file can be created.
    """
    try:
        text = os.fsdecode(os.fspath(path))
    except TypeError:
        raise ValueError(f"{kind} path: expected a file path, got {type(path).__name__}") from None
    if not text:
        raise ValueError(f"{kind} path: empty")
    ext = os.path.splitext(text)[1].lower()
    if ext not in extensions:
        raise ValueError(
            f"cannot write {text}: unknown {kind} extension {ext or '(none)'!r} (use {', '.join(extensions)})"
        )
    full = os.path.abspath(text)
    target = os.path.realpath(full)  # a symbolic link is written through to its target
    folder = os.path.dirname(target)
    if not os.path.isdir(folder):
        raise ValueError(f"cannot write {text}: folder {folder} does not exist")
    if os.path.isdir(target):
        raise ValueError(f"cannot write {text}: it is a folder")
    _refuse_special(target, text)
    if os.path.exists(target) and not os.access(target, os.W_OK):
        raise ValueError(f"cannot write {text}: the file exists and is read-only")
    try:
        fd, probe = tempfile.mkstemp(prefix=".warp_ccd-probe-", dir=folder)
    except OSError as exc:
        raise ValueError(f"cannot write {text}: cannot create files in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.remove(probe)
    return full, ext


_SPECIAL = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
            (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _refuse_special(target: str, text: str) -> None:
    """Raises ValueError where ``target`` exists and is not a regular file (``text``: the path as given)."""
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return
    what = next((name for test, name in _SPECIAL if test(mode)), "not a regular file")
    via = "" if target == os.path.abspath(text) else f" (through a link to {target})"
    raise ValueError(f"cannot write {text}: it is {what}{via}, not a regular file: refused rather than replaced")


def _remove_quietly(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


class PendingFile:
    """A hidden temporary file beside ``path`` that becomes ``path`` on :meth:`commit`.

    The temporary file keeps the destination's extension (file-format plugins pick the format
    by extension). It is removed by :meth:`discard`, or when this object is garbage collected or
    the interpreter exits without a commit.

    Args:
        path: absolute destination path (checked with :func:`check_output_path`).

    Attributes:
        path: the destination.
        temp_path: where to write until :meth:`commit`.

    Raises:
        ValueError: the temporary file cannot be created.
    """

    def __init__(self, path: str):
        self.path = path
        self._target = os.path.realpath(path)  # a symbolic link stays one: its target is replaced
        folder, name = os.path.split(self._target)
        ext = os.path.splitext(name)[1]
        try:
            fd, self.temp_path = tempfile.mkstemp(prefix=f".{name}.", suffix=f".partial{ext}", dir=folder)
        except OSError as exc:
            raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None
        os.close(fd)
        self._cleanup = weakref.finalize(self, _remove_quietly, self.temp_path)
        self.done = False

    def commit(self) -> str:
        """Renames the temporary file to the destination, with ordinary permission bits.

        The new file gets the permission bits of the file it replaces, or ``0o666 & ~umask``
        (``mkstemp`` creates ``0o600``).

        Returns:
            The destination path.

        Raises:
            ValueError: the rename failed, or the destination is now not a regular file (the
                temporary file is removed).
        """
        try:
            _refuse_special(self._target, self.path)
            os.chmod(self.temp_path, _new_file_mode(self._target))
            os.replace(self.temp_path, self._target)
        except ValueError:
            self.discard()
            raise
        except OSError as exc:
            self.discard()
            raise ValueError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._cleanup.detach()
        self.done = True
        return self.path

    def discard(self) -> None:
        """Removes the temporary file; the destination is left as it was."""
        self._cleanup()
        self.done = True


def prepare_text(path, text: str, extensions: tuple[str, ...], kind: str) -> PendingFile:
    """``text`` written to a temporary file beside ``path`` (checked with :func:`check_output_path`), not yet
    in place.

    Returns:
        The :class:`PendingFile`: :meth:`PendingFile.commit` moves it to ``path``, :meth:`PendingFile.discard`
        removes it.

    Raises:
        ValueError: ``path`` is not a writable destination of one of ``extensions``.
    """
    full, _ = check_output_path(path, extensions, kind)
    pending = PendingFile(full)
    try:
        with open(pending.temp_path, "w", encoding="utf-8") as fh:
            fh.write(text)
    except BaseException:
        pending.discard()
        raise
    return pending


def _new_file_mode(path: str) -> int:
    """Permission bits of the file at ``path`` if there is one, else ``0o666 & ~umask``."""
    try:
        return os.stat(path).st_mode & 0o777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


def commit_all(pending) -> list[str]:
    """Moves every pending file into place, after all of them were written.

    Call it once every output is complete: an error or an interrupt before it leaves every
    destination as it was. If one rename fails, the files not yet moved are discarded (those
    before it are in place).

    Args:
        pending: :class:`PendingFile` objects.

    Returns:
        Their destination paths, in order.

    Raises:
        ValueError: a rename failed (naming the destination).
    """
    pending = list(pending)
    done = []
    try:
        for p in pending:
            done.append(p.commit())
    except BaseException:
        for p in pending:
            if not p.done:
                p.discard()
        raise
    return done


def same_file(a, b) -> bool:
    """Whether two paths name one file: equal after symbolic links are resolved (and case, where
    the file system ignores it), or the same existing file (``os.path.samefile``).

    Args:
        a, b: paths (str or path-like); either may not exist.
    """
    ra, rb = os.path.realpath(a), os.path.realpath(b)
    if os.path.normcase(ra) == os.path.normcase(rb):
        return True
    try:
        return os.path.samefile(ra, rb)
    except OSError:
        return False
