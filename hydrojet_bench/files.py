"""Files the bench writes and reads, safely: nothing recorded is overwritten by accident,
no two processes both get one name, and an input that is not a regular file (a FIFO, a
directory, a device) is refused instead of read forever.

Writing is exclusive: a new file is created with ``O_EXCL`` (`create_new`,
`create_numbered`), or written whole beside its destination and then linked into place,
which fails if the destination appeared meanwhile (`publish`). ``overwrite=True`` is the
user's explicit ``--overwrite``.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO, TypeVar

from .errors import UserError

Result = TypeVar("Result")
OVERWRITE_HINT = "choose another file or pass --overwrite"


def refuse_existing(path: Path, what: str) -> UserError:
    """The one-line refusal to overwrite ``path``, a ``what`` (e.g. "session log")."""
    return UserError(f"{path}: a {what} already exists there; {OVERWRITE_HINT}")


def check_writable_target(path: Path, what: str, *, overwrite: bool) -> None:
    """Refuse, with one line, a ``path`` that is a directory, whose folder is missing, or
    (unless ``overwrite``) that exists; ``what`` names the file (e.g. "session log")."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: is a directory; give the {what} a file name")
    if not path.parent.is_dir():
        raise UserError(f"{path}: cannot write the {what}: its folder {path.parent} does not exist")
    if path.exists() and not overwrite:
        raise refuse_existing(path, what)


def check_folder_target(folder: Path, what: str) -> None:
    """Refuse, with one line, a ``folder`` to write into that could not be created or
    written: an existing file there or above it, or a nearest existing folder this user
    may not write into. Said before the work (a session, a diagnosis), not after it."""
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not existing.is_dir():
        raise UserError(f"cannot create {what} {folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"cannot create {what} {folder}: {existing} is not writable")
    # Permission bits do not say everything (root may write anywhere but /proc, a full or
    # read-only disk): make the missing folders and take them away again.
    made = []
    try:
        for missing in reversed([p for p in (folder, *folder.parents) if p != existing and not p.exists()
                                 and existing in p.parents]):
            missing.mkdir()
            made.append(missing)
    except OSError as error:
        raise UserError(f"cannot create {what} {folder}: {error.strerror or error}") from None
    finally:
        for created in reversed(made):
            created.rmdir()


def check_replaceable(path: Path, what: str, of_its_kind: Callable[[bytes], bool]) -> None:
    """Refuse, with one line, to replace an existing ``path`` whose first bytes are not
    ``of_its_kind``: a derived output (a parameter file, a JSON document) replaces an
    earlier one of its kind, never a session log, a table or a profile named as the
    output by mistake (``calibrate run.mcap -o run.mcap``). An empty file may go."""
    if Path(path).is_dir():
        raise UserError(f"{path}: is a directory; give the {what} a file name")
    try:
        with Path(path).open("rb") as file:
            head = file.read(64)
    except OSError:
        return  # nothing there (or nothing readable): the write itself says what is wrong
    if head and not of_its_kind(head):
        raise UserError(f"{path}: exists and is not a {what}; refusing to replace it (is it an input?): give the "
                        f"{what} another path")


def make_folder_for(path: Path) -> None:
    """Create the missing folders above ``path``, or say in one line why not."""
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"{path}: cannot create its folder {Path(path).parent}: {error.strerror or error}") from None


def create_new(path: Path, what: str, *, overwrite: bool = False) -> BinaryIO:
    """``path`` opened for binary writing; created exclusively (two processes cannot both
    succeed) unless ``overwrite``."""
    check_writable_target(path, what, overwrite=overwrite)
    try:
        return Path(path).open("wb" if overwrite else "xb")
    except FileExistsError:
        raise refuse_existing(path, what) from None
    except OSError as error:
        raise UserError(f"{path}: cannot write the {what}: {error.strerror or error}") from None


def create_numbered(path: Path, what: str, attempts: int = 1000) -> Path:
    """Reserve a new, empty file at ``path``, or at ``stem-1.suffix``, ``stem-2.suffix``...
    if taken (e.g. by a session started in the same second), and return its path."""
    path = Path(path)
    make_folder_for(path)
    check_writable_target(path, what, overwrite=True)
    for number in range(attempts):
        candidate = path if number == 0 else path.with_name(f"{path.stem}-{number}{path.suffix}")
        try:
            candidate.open("xb").close()
            return candidate
        except FileExistsError:
            continue
        except OSError as error:
            raise UserError(f"{candidate}: cannot write the {what}: {error.strerror or error}") from None
    raise UserError(f"{path}: {attempts} {what}s of that name exist already; choose another name")


def publish(path: Path, what: str, write: Callable[[Path], Result], *, overwrite: bool = False) -> Result:
    """Write ``path`` whole: ``write`` fills a partial file beside it, which then takes the
    name ``path`` (by a hard link, which fails if ``path`` appeared meanwhile, unless
    ``overwrite``). A reader never sees half a file; nothing is left behind on failure."""
    path = Path(path)
    check_writable_target(path, what, overwrite=overwrite)
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        result = write(partial)
        if overwrite:
            os.replace(partial, path)
        else:
            os.link(partial, path)
    except FileExistsError:
        raise refuse_existing(path, what) from None
    except OSError as error:
        raise UserError(f"{path}: cannot write the {what}: {error.strerror or error}") from None
    finally:
        partial.unlink(missing_ok=True)
    return result


def check_regular_input(path: Path) -> None:
    """Refuse, with one line, an input that is missing or not a regular file (a FIFO with
    no writer would block its reader forever, a directory cannot be read)."""
    try:
        mode = os.stat(path).st_mode
    except OSError as error:
        raise UserError(f"{path}: cannot read: {error.strerror or error}") from None
    if not stat.S_ISREG(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "not a regular file"
        raise UserError(f"{path}: cannot read: it is {kind}; expected a regular file")
