"""Where generated models, compiled libraries and results live, and how folders are written.

* ``generated/`` at the project root holds the committed models of the bundled scenes
  (``generated/<scene>_<formulation>/``); ``FLEXBODY_GENERATED`` overrides it.
* The cache (``FLEXBODY_CACHE``, default ``~/.cache/flexbody``) holds models derived on
  demand (``models/<digest>/``) and compiled C libraries (``lib/<sha256>.so``).
* A result folder (``flexbody run --out DIR``) is written whole or not at all:
  :func:`check_output_dir` refuses an unusable location before any work, and
  :func:`staged_folder` replaces the folder in one rename.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError, shown

PROJECT_ROOT = Path(__file__).resolve().parents[2]


def generated_root() -> Path:
    """The committed ``generated/`` folder: the checkout's, or the installed data package
    ``flexbody_generated`` (a non-editable install); ``FLEXBODY_GENERATED`` overrides both."""
    if "FLEXBODY_GENERATED" in os.environ:
        return Path(os.environ["FLEXBODY_GENERATED"])
    local = PROJECT_ROOT / "generated"
    if local.is_dir():
        return local
    spec = importlib.util.find_spec("flexbody_generated")
    if spec is not None and spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return local


def cache_root() -> Path:
    """The cache folder for on-demand models and compiled libraries."""
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "flexbody"
    return Path(os.environ.get("FLEXBODY_CACHE", default))


def model_dir_name(scene_name: str, formulation: str) -> str:
    return f"{scene_name}_{formulation}"


def check_output_dir(text: str, option: str = "--out") -> Path:
    """The folder ``text`` names, if a result can replace it; checked before any work.

    The result replaces the folder whole (see :func:`staged_folder`), so the folder must
    be new, empty or a previous result (it holds ``summary.json``); it must not be the
    current folder or one of its parents; and its nearest existing ancestor must be a
    folder in which this process can create folders (probed with an empty temporary
    folder that is removed at once).  Nothing is left behind.

    Raises
    ------
    InputError
        One line naming the option, the value and what is wrong.
    """

    def refuse(why: str) -> InputError:
        return InputError(f"`{option}` = {shown(text)}: {why}")

    if not text or not text.strip():
        raise refuse("is empty; name a folder for the results, e.g. out/")
    path = Path(text)
    absolute = Path(os.path.abspath(path))
    cwd = Path.cwd()
    if absolute == cwd or absolute in cwd.parents:
        raise refuse("is the current folder or one of its parents; the results replace the folder whole, "
                     "so name a new folder, e.g. out/")
    if path.is_symlink():
        raise refuse("is a symbolic link; the results replace the folder whole, so name the folder itself")
    if path.exists():
        if not path.is_dir():
            raise refuse("exists and is not a folder")
        try:
            entries = sorted(os.listdir(path))
        except OSError as exc:
            raise refuse(f"cannot be read ({exc.strerror})") from None
        if entries and "summary.json" not in entries:
            raise refuse(f"holds other files ({shown(entries)}) and no previous result (summary.json); the results "
                         "replace the folder whole, so name a new or empty folder")
    ancestor = absolute.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise refuse(f"{ancestor} is a file, not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".flexbody-probe-", dir=ancestor))
    except OSError as exc:
        raise refuse(f"cannot create a folder in {ancestor} ({exc.strerror or exc})") from None
    return path


@contextmanager
def staged_folder(target: str | Path) -> Iterator[Path]:
    """Write a folder's files into a temporary folder, then put it in ``target``'s place.

    Yields an empty folder beside ``target`` (same file system, so renames are atomic).
    When the block ends without an exception, an existing ``target`` is renamed away,
    the new folder is renamed to ``target``, and the old one is deleted: ``target`` then
    holds exactly the files written in the block, never a mix of two runs.  On an
    exception the temporary folder is removed and ``target`` is untouched.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}-new-", dir=target.parent))
    try:
        yield staging
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp's folder is private; a result folder is not
        old = None
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}-old-", dir=target.parent))
            os.replace(target, old)  # onto the empty placeholder: a rename of the old folder
        try:
            os.replace(staging, target)
        except BaseException:
            if old is not None:
                os.replace(old, target)
            raise
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


@contextmanager
def staged_file(target: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``target``; when the block succeeds it replaces
    ``target`` in one rename (a reader never sees a half-written file).  On an exception
    the temporary file is removed."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}-", suffix=suffix, dir=target.parent)
    os.close(fd)
    try:
        yield Path(name)
        os.replace(name, target)
    except BaseException:
        Path(name).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
