"""The notebooks' cached run: the embedded default flight's dataset and SLAM
result, computed once and then read from :func:`helpers.paths.cache_dir`.

A cached run is two files named by its key, a hash of what decides its
numbers (the configuration, the core package's files, the libraries'
versions): ``slam-<key>.npz`` holds its arrays and, as JSON, how they fit
together; ``slam-<key>.json`` holds the key's parts and the ``.npz``'s size
and SHA-256. Reading runs no code: NumPy reads the arrays with
``allow_pickle=False``, and the objects are rebuilt only from classes of the
package's ``slam`` and ``config`` layers, their state set without calling
them. A run that fails any check is computed again, with one warning; a cache
that cannot be written costs only the cache.
"""

from __future__ import annotations

import hashlib
import importlib
import io
import json
import logging
import platform
from contextlib import suppress
from importlib import metadata
from pathlib import Path

import numpy as np

from helpers import paths
from helpers.config.files import config_to_toml
from helpers.config.tables import Config, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.sim.dataset import Dataset, create_dataset, is_default
from helpers.slam.flight_fit import fit_to_flight, flight_of
from helpers.slam.pipeline import run_slam
from helpers.slam.slam import SlamResult

log = logging.getLogger(__name__)

PICTURE_PACKAGES = ("viz", "site", "exercises")  # subpackages that draw, publish or check, never change a run's numbers
FORMAT = 1  # of the two files; a change makes every older run a miss
# Whose versions decide a run's numbers besides the package's own files (the package's version included).
LIBRARIES = ("aerial-lidar-slam-helpers", "numpy", "scipy", "open3d", "small_gicp", "gtsam", "laspy", "lazrs")
STORED_LAYERS = ("helpers.slam.", "helpers.config.")  # the modules whose classes a cached run may hold


def default_config(dataset: Dataset, config: Config) -> Config:
    """``config`` fitted to ``dataset``'s flight as ``python -m helpers run``
    fits it (:func:`helpers.slam.flight_fit.fit_to_flight`). On the embedded default
    the fit keeps every value but the descriptor grid, 3 m instead of the
    reference's 1.5 m: the same trajectory, loops and map error (README,
    "Your own data"), the run 23 s against 30 s on two cores."""
    return fit_to_flight(flight_of(dataset), config)[0]


def core_fingerprint() -> bytes:
    """The SLAM core's files (every file of the package outside
    :data:`PICTURE_PACKAGES`: code and the shipped flight), names and contents,
    in a fixed order: what decides a run's numbers."""
    root = Path(__file__).parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        relative = path.relative_to(root)
        if path.is_file() and relative.parts[0] not in PICTURE_PACKAGES and "__pycache__" not in relative.parts:
            digest.update(relative.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.digest()


def library_versions() -> dict[str, str]:
    """The installed version of Python and of each of :data:`LIBRARIES` ("none" if missing)."""
    versions = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "none"
    return versions


def default_run(config: Config | None = None, dataset: Dataset | None = None) -> tuple[Dataset, SlamResult]:
    """The dataset and the SLAM result of the embedded default, computed
    once and then read from :func:`helpers.paths.cache_dir` (keyed by the
    configuration, the core package's files and the libraries' versions, so
    any change recomputes; so does a file that fails its check, with a
    warning). Notebooks 4 to 7 start from here instead of from hidden state;
    two of them computing it at once each write a whole file. A cache that
    cannot be written is said in one warning and the result returned.
    ``config``: None is the run ``python -m helpers run`` makes of the
    default: the defaults with the noise seed of
    :func:`~helpers.config.tables.noise_seed_from_environment`, fitted to the flight
    (:func:`default_config`). A configuration given is taken as it is.
    ``dataset``: the embedded default already cast with ``config``'s sensor,
    returned as it is (a notebook's second run of the same flight then casts
    no scan again); None casts it."""
    fit = config is None
    config = config or Config().with_values(sensor={"seed": noise_seed_from_environment()})
    folder = paths.cache_dir()  # a bad place is said before anything is computed
    if dataset is None:
        dataset = create_dataset(sensor=config.sensor)
    elif not is_default(dataset, config.sensor):
        raise SlamError(
            "default_run's dataset must be the embedded default (the default scene, the shipped loop) cast with "
            f"the configuration's sensor; this one is the {dataset.name}"
            f"{'' if dataset.sensor == config.sensor else ' cast with another sensor'}"
        )
    if fit:
        config = default_config(dataset, config)
    described = {
        "format": FORMAT,
        "type": _class_name(SlamResult),
        "config": config_to_toml(config),
        "core": core_fingerprint().hex(),
        "versions": library_versions(),
    }
    described["key"] = hashlib.sha256(json.dumps(described, sort_keys=True).encode()).hexdigest()[:16]
    paths.sweep_cache(folder)
    result = _read(folder, described, config)
    if result is None:
        result = run_slam(dataset, config)
        _store(folder, described, result)
    return dataset, result


def _read(folder: Path, described: dict, config: Config) -> SlamResult | None:
    """The run cached under ``described``'s key, if it passes every check; None (with a warning if one failed)."""
    record = folder / f"slam-{described['key']}.json"
    try:
        with paths.locked(folder, shared=True):  # no writer between the record and its data
            found = paths.read_checked(record, described)
        if found is None:
            return None
        result = decode(found[1])
        if not isinstance(result, SlamResult) or result.config != config:
            raise paths.Damaged(f"{found[0].name} holds another run than its record says")
    except (FileNotFoundError, NotADirectoryError):
        return None  # no cache folder yet, or a file in its place (said when the run is stored)
    except (paths.Damaged, OSError, ValueError) as exc:
        log.warning("the cached run in %s failed its check (%s): computing it again", folder, _one_line(exc))
        return None
    return result


def _store(folder: Path, described: dict, result) -> None:
    """Write ``result`` into the cache folder, or say in one warning why it could not be."""
    npz = folder / f"slam-{described['key']}.npz"
    try:
        data = encode(result)
        folder.mkdir(parents=True, exist_ok=True)
        with paths.locked(folder):
            try:
                paths.write_checked(npz, lambda f: f.write(data), described)
            except BaseException:
                for leftover in (npz, paths.record_of(npz)):  # neither a record without its data nor the reverse
                    with suppress(OSError):
                        leftover.unlink(missing_ok=True)
                raise
    except (OSError, TypeError) as exc:
        there = next((p for p in (folder, *folder.parents) if p.exists()), folder)
        why = f"{there} is a file, not a folder" if not there.is_dir() else _one_line(exc)
        log.warning(
            "the run was not saved in the cache folder %s (%s): it will be computed again next time; "
            "$%s names another folder",
            folder,
            why,
            paths.CACHE_VARIABLE,
        )
        return
    paths.evict(folder, keep=npz)


def encode(value) -> bytes:
    """``value`` (a run: dataclasses of numbers, strings, arrays, lists, tuples and dicts of them) as the bytes
    of a ``.npz``: every array as its own member, and ``tree``, the JSON of how they fit together."""
    arrays: list[np.ndarray] = []
    tree = json.dumps(_encode(value, arrays)).encode()
    buffer = io.BytesIO()
    np.savez(buffer, tree=np.frombuffer(tree, np.uint8), **{f"a{i}": a for i, a in enumerate(arrays)})
    return buffer.getvalue()


def decode(data: bytes):
    """What :func:`encode` wrote, read back without running any code it names (a :class:`ValueError` if it is
    not such a file, or names a class outside :data:`STORED_LAYERS`)."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as members:
            return _decode(json.loads(members["tree"].tobytes()), members)
    except ValueError:
        raise
    except Exception as exc:  # a file of another shape raises many types: it is not a cached run
        raise ValueError(f"not a cached run ({_one_line(exc)})") from None


def _encode(value, arrays: list):
    kind = type(value)
    if value is None or kind in (bool, int, float, str):
        return value
    if kind is np.ndarray and not value.dtype.hasobject:
        arrays.append(value)
        return {"array": len(arrays) - 1}
    if isinstance(value, np.generic) and not isinstance(value, np.object_):
        arrays.append(np.asarray(value))
        return {"scalar": len(arrays) - 1}
    if kind is list:
        return [_encode(v, arrays) for v in value]
    if kind is tuple:
        return {"tuple": [_encode(v, arrays) for v in value]}
    if kind is dict:
        return {"dict": [[_encode(k, arrays), _encode(v, arrays)] for k, v in value.items()]}
    if kind.__module__.startswith(STORED_LAYERS) and hasattr(value, "__dict__"):
        return {"object": [_class_name(kind), {k: _encode(v, arrays) for k, v in vars(value).items()}]}
    raise TypeError(f"a {kind.__module__}.{kind.__qualname__} cannot be stored")


def _decode(node, members):
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if isinstance(node, list):
        return [_decode(v, members) for v in node]
    ((kind, value),) = node.items()
    if kind in ("array", "scalar"):
        array = members[f"a{int(value)}"]
        return array if kind == "array" else array[()]
    if kind == "tuple":
        return tuple(_decode(v, members) for v in value)
    if kind == "dict":
        return {_decode(k, members): _decode(v, members) for k, v in value}
    if kind == "object":
        name, state = value
        made = object.__new__(_stored_class(name))  # no __init__, __setstate__ or __new__ of ours is called
        made.__dict__.update({k: _decode(v, members) for k, v in state.items()})
        return made
    raise ValueError(f"unknown node {kind!r}")


def _stored_class(name: str) -> type:
    """The class ``module:qualname`` names, if a module of :data:`STORED_LAYERS` defines it."""
    module, _, qualname = name.partition(":")
    if not module.startswith(STORED_LAYERS) or not qualname.isidentifier():
        raise ValueError(f"a cached run may not hold a {name}")
    found = getattr(importlib.import_module(module), qualname, None)
    if not isinstance(found, type) or found.__module__ != module or found.__new__ is not object.__new__:
        raise ValueError(f"a cached run may not hold a {name}")
    return found


def _class_name(kind: type) -> str:
    return f"{kind.__module__}:{kind.__qualname__}"


def _one_line(exc: BaseException) -> str:
    return " ".join(str(getattr(exc, "strerror", None) or exc).split())
