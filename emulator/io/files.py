"""Generic files: atomic writes, JSON metadata, ``results.json``, reports, figures, arrays.

Every file exposim writes goes through :func:`atomic_write_bytes`: a temporary file in the
destination folder, then :func:`os.replace`, so an interrupted write never leaves a partial
file under the final name; an existing file is replaced only when asked (``overwrite``).

Two JSON flavours, each with one reader and one writer:

* **metadata** (``run.json``, ``exposim.json`` of recordings and stacks, ``scene.json``):
  :func:`write_metadata` / :func:`read_metadata`;
* **results** (``results.json`` of every command and study): :func:`write_results` /
  :func:`read_results`.  Figures must be finite (a NaN is refused, naming its key), numpy
  scalars and arrays become JSON numbers and lists, paths become strings;
  :func:`prepare_output` refuses a folder that already holds results unless forced.

Reports and figures: :func:`write_text` (markdown), :func:`save_figure` (a matplotlib
figure as PNG), :func:`write_arrays` / :func:`read_arrays` (the arrays behind the figures,
``.npz``).  :func:`format_timestamp_s` writes integer nanoseconds as exact decimal seconds
(TUM poses and ``times.txt``).
"""

from __future__ import annotations

import io
import json
import math
import os
import secrets
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError, ExposimError, OutputExistsError

__all__ = [
    "strict_json",
    "read_bytes",
    "RESULTS_FILE",
    "REPORT_FILE",
    "atomic_write_bytes",
    "make_staging_dir",
    "write_text",
    "read_text",
    "to_jsonable",
    "parse_json_object",
    "write_metadata",
    "read_metadata",
    "write_results",
    "read_results",
    "prepare_output",
    "first_free",
    "save_figure",
    "write_arrays",
    "read_arrays",
    "format_timestamp_s",
]

#: Machine-readable figures of every command and study.
RESULTS_FILE = "results.json"
#: The short markdown report beside them.
REPORT_FILE = "report.md"


# ---------------------------------------------------------------------------- bytes and text
def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    An interrupted write never leaves a partial file under the final name.  Refuses to
    replace an existing file unless ``overwrite`` (:class:`OutputExistsError`).  Creates the
    parent folder.
    """
    path = Path(path)
    if not overwrite and (path.exists() or path.is_symlink()):
        raise OutputExistsError(f"{path}: exists; refusing to overwrite (use --force / overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _unique(path.parent, f".{path.name}.", ".part", lambda p: os.open(p, _NEW_FILE_FLAGS, 0o666))
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise with_path(exc, path) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def with_path(exc: OSError, path) -> OSError:
    """``exc`` naming ``path`` when it names no file (a write's ``No space left on device``)."""
    if exc.filename is not None:
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), os.fspath(path))


#: Flags of a new temporary file: created, never an existing one, never through a symlink.
_NEW_FILE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def _unique(folder: Path, prefix: str, suffix: str, create):
    """``(create(path), path)`` for a new random name ``prefix + 8 hex + suffix`` in ``folder``.

    ``create`` must fail with :class:`FileExistsError` on an existing name (``O_EXCL``,
    :func:`os.mkdir`).  Unlike :mod:`tempfile` (mode 0600 / 0700), the mode given to ``create``
    goes through the process umask, as for any file the user creates.
    """
    for _ in range(100):
        candidate = folder / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            return create(candidate), candidate
        except FileExistsError:
            continue
    raise FileExistsError(f"{folder}: no free temporary name {prefix}*{suffix} after 100 tries")


def make_staging_dir(parent: str | os.PathLike, prefix: str) -> Path:
    """A new, empty folder ``parent/prefix<random>`` (mode 0777 less the umask: 0755 under 0022).

    For writers that fill a folder and rename it into place when complete (the synthetic
    datasets), so that the published folder has the permissions :func:`os.mkdir` gives.
    """
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    return _unique(parent, prefix, "", lambda p: os.mkdir(p, 0o777))[1]


def write_text(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Write UTF-8 text (a markdown report, a text table) atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"), overwrite=overwrite)


def read_bytes(path: str | os.PathLike) -> bytes:
    """The bytes of a file (a figure to embed in a report)."""
    return Path(path).read_bytes()


def read_text(path: str | os.PathLike, error: type[Exception] = DatasetError) -> str:
    """UTF-8 text of a file; ``error`` naming the file when it is not text.

    A missing file raises :class:`FileNotFoundError` naming it.
    """
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: not a UTF-8 text file") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, expected a file") from None


# ---------------------------------------------------------------------------- JSON
def strict_json(obj, *, indent=None, reasons: Mapping | None = None) -> str:
    """``obj`` as strict JSON text (no NaN or Infinity, which strict parsers refuse): a non-finite
    figure becomes ``null``, and a mapping at the top level gets ``"null_reasons"``, key path ->
    why (``reasons`` by key path, else what the value was)."""
    found: dict[str, str] = {}

    def clean(value, where):
        if isinstance(value, Mapping):
            return {str(k): clean(v, f"{where}.{k}" if where else str(k)) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if isinstance(value, np.ndarray):
            return clean(value.tolist(), where)
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, float) and not math.isfinite(value):
            found[where] = (reasons or {}).get(where) or f"not a finite number ({value!r})"
            return None
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        return value

    out = clean(obj, "")
    if found and isinstance(out, dict):
        out.setdefault("null_reasons", {}).update(found)
    return json.dumps(out, indent=indent, allow_nan=False, default=str)


def to_jsonable(obj, *, where: str = "", float_digits: int | None = None):
    """``obj`` with numpy scalars/arrays, tuples and paths turned into JSON types.

    Non-finite floats are refused with :class:`ExposimError` naming their key path (JSON
    has no NaN, and every figure exposim reports must be a number).  ``float_digits``
    rounds floats to that many significant digits (stable text); None keeps them exact.
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v, where=f"{where}.{k}" if where else str(k), float_digits=float_digits)
                for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, where=f"{where}[{i}]", float_digits=float_digits) for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), where=where, float_digits=float_digits)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        if not math.isfinite(obj):
            raise ExposimError(f"non-finite number {obj!r} at {where or 'top level'} (every figure must be finite)")
        return float(f"{obj:.{float_digits}g}") if float_digits else obj
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    raise ExposimError(f"cannot write {type(obj).__name__} at {where or 'top level'} as JSON")


def _dumps(obj, *, indent: int, float_digits: int | None = None) -> bytes:
    return (json.dumps(to_jsonable(obj, float_digits=float_digits), indent=indent, allow_nan=False) + "\n").encode()


def parse_json_object(data: bytes | str, name: str | os.PathLike, error: type[Exception] = DatasetError) -> dict:
    """The JSON object in ``data`` (the content of ``name``); ``error`` naming it if malformed."""
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError:
            raise error(f"{name}: not a UTF-8 text file (expected JSON)") from None
    try:
        obj = json.loads(data)
    except json.JSONDecodeError as exc:
        raise error(f"{name}: malformed JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise error(f"{name}: expected a JSON object, got {type(obj).__name__}")
    return obj


def _read_json_object(path: Path, error: type[Exception]) -> dict:
    return parse_json_object(path.read_bytes(), path, error)


def write_metadata(path: str | os.PathLike, data: Mapping, *, overwrite: bool = False) -> Path:
    """Write a metadata JSON object (``run.json``, ``exposim.json``, ``scene.json``) atomically."""
    return atomic_write_bytes(path, _dumps(data, indent=2), overwrite=overwrite)


def read_metadata(path: str | os.PathLike, error: type[Exception] = DatasetError, *, required: bool = False) -> dict:
    """The JSON object in a metadata file.

    An absent file gives ``{}`` (optional metadata) unless ``required``, then
    :class:`FileNotFoundError`.  A file that is not a JSON object raises ``error`` naming it.
    """
    path = Path(path)
    if not path.is_file():
        if required:
            raise FileNotFoundError(f"{path}: not found")
        return {}
    return _read_json_object(path, error)


def write_results(
    path: str | os.PathLike, results: Mapping, *, overwrite: bool = True, float_digits: int | None = None
) -> Path:
    """Write a ``results.json`` (indent 1, keys in insertion order), atomically.

    ``float_digits`` rounds floats to that many significant digits (the validation studies
    use 12 for stable text); the default keeps them exact.  Raises :class:`ExposimError`
    for a non-finite figure, naming its key.
    """
    return atomic_write_bytes(path, _dumps(results, indent=1, float_digits=float_digits), overwrite=overwrite)


def read_results(path: str | os.PathLike) -> dict:
    """The JSON object of a ``results.json`` (:class:`DatasetError` if malformed)."""
    path = Path(path)
    if path.is_dir():
        path = path / RESULTS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: results not found")
    return _read_json_object(path, DatasetError)


def first_free(base: str | os.PathLike, start: int = 2) -> Path:
    """The first of ``base-{start}``, ``base-{start+1}``, ... that does not exist (for outputs that never overwrite)."""
    base = Path(base)
    k = int(start)
    while (base.with_name(f"{base.name}-{k}")).exists():
        k += 1
    return base.with_name(f"{base.name}-{k}")


def prepare_output(folder: str | os.PathLike, *, force: bool = False) -> Path:
    """Create ``folder`` for results; refuse one that already holds ``results.json`` unless ``force``."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputExistsError(f"{folder}: exists and is not a folder")
    if (folder / RESULTS_FILE).exists() and not force:
        raise OutputExistsError(f"{folder / RESULTS_FILE}: exists; refusing to overwrite (use --force)")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


# ---------------------------------------------------------------------------- figures and arrays
def save_figure(fig, path: str | os.PathLike, *, dpi: int = 110, overwrite: bool = True) -> Path:
    """Render a matplotlib figure to PNG and write it atomically (the figure is not closed)."""
    import warnings

    buf = io.BytesIO()
    with warnings.catch_warnings():  # layout advice from matplotlib is no message for the user
        warnings.simplefilter("ignore", UserWarning)
        fig.savefig(buf, format="png", dpi=dpi)
    return atomic_write_bytes(path, buf.getvalue(), overwrite=overwrite)


def write_arrays(path: str | os.PathLike, arrays: Mapping, *, overwrite: bool = True) -> Path:
    """Write named arrays as a compressed ``.npz`` (the arrays behind a study's figures)."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **{str(k): np.asarray(v) for k, v in arrays.items()})
    return atomic_write_bytes(path, buf.getvalue(), overwrite=overwrite)


def read_arrays(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` written by :func:`write_arrays` (no pickled objects)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: arrays not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (ValueError, OSError) as exc:
        raise DatasetError(f"{path}: not a readable .npz file ({exc})") from None


# ---------------------------------------------------------------------------- text formats
def format_timestamp_s(timestamp_ns: int) -> str:
    """Integer nanoseconds as exact decimal seconds with 9 decimals.

    >>> format_timestamp_s(1695668703364771328)
    '1695668703.364771328'
    >>> format_timestamp_s(-5)
    '-0.000000005'
    """
    ts = int(timestamp_ns)
    sign = "-" if ts < 0 else ""
    ts = abs(ts)
    return f"{sign}{ts // 1_000_000_000}.{ts % 1_000_000_000:09d}"
