"""qbricks: open, render, probe and bake AMR brick files (``.qbk``) from Python.

The work is done by the same Rust libraries as the ``qbricks-view`` and ``qbricks-bake``
command-line tools; a keyword argument of :meth:`Dataset.render` means exactly what the
flag of the same name means to ``qbricks-view render`` (``look_at`` is ``--look-at``), and
the picture is the one the CLI writes, pixel for pixel.

>>> import qbricks
>>> ds = qbricks.open("data/wake_small.qbk")
>>> img = ds.render(width=256, height=256)      # qbricks.Image, img.array is (H, W, 4) uint8
>>> values = ds.probe([[0.0, 0.0, 0.0]])         # {"q": array([...]), ..., "gradient": ...}
"""

from __future__ import annotations

import json
import os
from collections.abc import MutableMapping
from typing import Any, Dict, Iterator, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _qbricks
from ._qbricks import FormatError

__all__ = ["open", "bake", "Dataset", "Image", "ViewState", "FormatError", "__version__"]
__version__ = _qbricks.__version__

PathLike = Union[str, "os.PathLike[str]"]

# Keyword → flag of `qbricks-view render` where the name is not the keyword with `-`.
_FLAG_NAMES = {"slices": "slice", "meshes": "mesh", "clip": "clip"}


def _flag_value(value: Any) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple, np.ndarray)):
        return ",".join(_flag_value(v) for v in value)
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        # The shortest text that reads back as the same double (numpy's repr is not it).
        return repr(float(value))
    return str(value)


def _flags(view: Mapping[str, Any]) -> list:
    """The CLI flags for the view keywords (None: not given; True: the flag alone)."""
    flags = []
    for key, value in view.items():
        if value is None or value is False:
            continue
        flag = "--" + _FLAG_NAMES.get(key, key).replace("_", "-")
        if value is True:
            flags.append(flag)
        elif key == "overlays" and not isinstance(value, str) and len(value) == 0:
            flags += [flag, "none"]
        elif key in ("clip", "slices", "meshes"):
            items = [value] if isinstance(value, str) else list(value)
            for item in items:
                if not isinstance(item, str) and key != "meshes":
                    # (origin, normal) pairs: "OX,OY,OZ:NX,NY,NZ".
                    origin, normal = item
                    item = _flag_value(origin) + ":" + _flag_value(normal)
                flags += [flag, _flag_value(item)]
        else:
            flags += [flag, _flag_value(value)]
    return flags


class ViewState(MutableMapping):
    """A view state: everything that makes a picture besides the data (camera, mode, iso
    values, colour map, lights, planes, meshes, size), as ``qbricks-view render
    --save-state`` writes it and ``--state`` reads it, and as the window saves it.

    A mapping of the JSON's keys (``vs["camera"]["eye"]``), also readable and settable as
    attributes (``vs.width = 800``). Every change is checked as a state file is: an unknown
    key or a bad value raises ``ValueError`` and leaves the state as it was. Made from a
    dict, a JSON file (:meth:`load`), JSON text (:meth:`from_json`), or by
    :meth:`Dataset.state` and :attr:`Image.state`; pass it as ``state=`` to
    :meth:`Dataset.render`. ``ViewState(d).to_dict()`` is ``d`` for any state the CLI
    wrote, and :meth:`save` writes what ``--save-state`` would."""

    __slots__ = ("_data",)

    def __init__(self, state: Union[Mapping[str, Any], "ViewState"]) -> None:
        data = state.to_dict() if isinstance(state, ViewState) else dict(state)
        object.__setattr__(self, "_data", self._checked(data))

    @staticmethod
    def _checked(data: Dict[str, Any]) -> Dict[str, Any]:
        return json.loads(_qbricks.normalize_state(json.dumps(data)))

    @classmethod
    def from_json(cls, text: str) -> "ViewState":
        """A state from its JSON text."""
        return cls(json.loads(text))

    @classmethod
    def load(cls, path: PathLike) -> "ViewState":
        """A state from a view-state JSON file, read and checked as ``--state`` reads it
        (``FileNotFoundError``; ``ValueError`` naming the file for a bad one)."""
        return cls(json.loads(_qbricks.load_state(os.fspath(path))))

    def to_json(self) -> str:
        """The JSON text, as ``--save-state`` writes it (without the final newline)."""
        return _qbricks.normalize_state(json.dumps(self._data))

    def to_dict(self) -> Dict[str, Any]:
        """A deep copy as plain dicts and lists."""
        return json.loads(json.dumps(self._data))

    def save(self, path: PathLike) -> None:
        """Writes the state as ``--save-state`` does (atomically: a temporary file renamed
        over ``path``); refuses (``ValueError``) to write over one of its meshes."""
        _qbricks.save_state(json.dumps(self._data), os.fspath(path))

    def replace(self, **changes: Any) -> "ViewState":
        """A copy with the given top-level keys changed."""
        data = self.to_dict()
        data.update(changes)
        return ViewState(data)

    # The mapping: reads give copies of nested values, so that a change always goes
    # through a check (vs["camera"]["fov"] = 5 changes a copy; vs["camera"] = {...} checks).
    def __getitem__(self, key: str) -> Any:
        return json.loads(json.dumps(self._data[key]))

    def __setitem__(self, key: str, value: Any) -> None:
        data = dict(self._data)
        data[key] = value
        object.__setattr__(self, "_data", self._checked(data))

    def __delitem__(self, key: str) -> None:
        data = dict(self._data)
        del data[key]
        object.__setattr__(self, "_data", self._checked(data))

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __getattr__(self, key: str) -> Any:
        try:
            return self[key]
        except KeyError:
            raise AttributeError(key) from None

    def __setattr__(self, key: str, value: Any) -> None:
        self[key] = value

    def __eq__(self, other: Any) -> bool:
        if isinstance(other, Mapping):
            return self._data == dict(other)
        return NotImplemented

    def __repr__(self) -> str:
        c = self._data.get("camera", {})
        return (f"<qbricks.ViewState {self._data.get('width')}x{self._data.get('height')} "
                f"{self._data.get('mode')} iso={self._data.get('iso')} eye={c.get('eye')}>")


class Image:
    """A rendered picture: ``array`` is (H, W, 4) uint8 RGBA (alpha 255), ``state`` the
    effective :class:`ViewState` (pass it back as ``state=`` to render the same view),
    ``depth`` the (H, W) float32 distance to the first surface (inf where none) when
    ``depth=True`` was asked for, ``aov`` the (H, W, C) float32 debug buffer when
    ``aov=`` was. Shows itself in Jupyter; :meth:`save` writes a PNG."""

    def __init__(self, array: np.ndarray, state: ViewState, depth: Optional[np.ndarray],
                 aov: Optional[np.ndarray] = None, inputs: Sequence[str] = ()):
        self.array = array
        self.state = state
        self.depth = depth
        self.aov = aov
        # The files the picture was made from, which save() never overwrites.
        self._inputs = list(inputs)

    @property
    def shape(self) -> Tuple[int, ...]:
        return self.array.shape

    def __array__(self, dtype=None, copy=None):
        return self.array if dtype is None else self.array.astype(dtype)

    def to_png(self) -> bytes:
        """The picture as PNG bytes (RGB, 8 bits), encoded as ``qbricks-view render``
        encodes its pictures."""
        return _qbricks.png_bytes(np.ascontiguousarray(self.array))

    def _repr_png_(self) -> bytes:
        return self.to_png()

    def save(self, path: PathLike) -> None:
        """Writes the picture as a PNG file, atomically (as the CLI writes its pictures);
        refuses (``ValueError``) to write over the brick file, state file or meshes it was
        rendered from."""
        _qbricks.save_png(np.ascontiguousarray(self.array), os.fspath(path), self._inputs)

    def __repr__(self) -> str:
        h, w = self.array.shape[:2]
        return f"<qbricks.Image {w}x{h}>"


class Dataset:
    """A validated ``.qbk`` file, memory-mapped for the life of this object (every array
    this object returns is a copy: nothing refers to the map once the object is gone).
    Made by :func:`open`."""

    def __init__(self, native: "_qbricks.Dataset") -> None:
        self._ds = native

    @property
    def path(self) -> str:
        return str(self._ds.path)

    @property
    def fields(self) -> Dict[str, Tuple[float, float]]:
        """Field name → (min, max), in the file's order."""
        return {name: (lo, hi) for name, lo, hi in self._ds.field_ranges}

    def info(self) -> Dict[str, Any]:
        """What ``qbricks-view info --json`` prints, as a dict."""
        return json.loads(self._ds.info_json())

    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """The data's bounding box in world coordinates: (min xyz, max xyz)."""
        i = self.info()
        return tuple(i["bounds_min"]), tuple(i["bounds_max"])

    @property
    def levels(self) -> list:
        """The refinement levels (as in ``info()["levels"]``)."""
        return self.info()["levels"]

    def histogram(self, field: str) -> Tuple[np.ndarray, np.ndarray]:
        """The histogram stored in the file for ``field``: (counts, bin edges), as
        ``numpy.histogram`` returns them (equal bins over the field's range)."""
        counts, lo, hi = self._ds.histogram(field)
        counts = np.asarray(counts, dtype=np.uint64)
        return counts, np.linspace(lo, hi, len(counts) + 1)

    def state(self, state: Any = None, **view: Any) -> ViewState:
        """The effective view state of ``render(state, **view)``, without rendering (what
        ``qbricks-view render --save-state`` writes)."""
        return ViewState(json.loads(self._ds.state_json(_native_state(state), _flags(view))))

    def render(
        self,
        state: Any = None,
        *,
        threads: Optional[int] = None,
        aov: Optional[str] = None,
        title: Optional[str] = None,
        depth: bool = False,
        **view: Any,
    ) -> Image:
        """Renders a view as ``qbricks-view render`` does, overlays included.

        ``state``: a :class:`ViewState` or a dict (as ``Image.state`` or ``Dataset.state``
        return, or a ``--save-state`` file holds) or the path of a view-state JSON file; None: the
        data's default view. The keywords are the CLI's view flags, applied over the state:
        ``width``, ``height``, ``mode`` ("iso", "dvr"), ``iso`` (a value or a list),
        ``iso_field``, ``iso_opacity``, ``iso_colour``, ``strategy``, ``step``, ``spp``,
        ``eye``, ``look_at``, ``up`` (3 numbers), ``fov``, ``ortho``, ``colour_field``,
        ``colormap``, ``colour_range`` ("visible", (lo, hi) or "lo,hi"), ``colour_centre``,
        ``log``, ``overlays`` (a list or "legend,axes,…"), ``clip`` and ``slices`` (lists
        of "x>0.5" or ((ox, oy, oz), (nx, ny, nz))), ``slice_opacity``, ``slice_contours``,
        ``slice_clip``, ``shadows``, ``preintegrated``, ``meshes``. ``threads``: worker
        threads (default all cores); ``aov``: a debug buffer instead of the shaded picture,
        at the first surface point of each pixel's centre ray: "normal" (``Image.aov`` is
        the (H, W, 3) unit normal), "depth" (the distance along the ray, inf on a miss),
        "level" (the finest refinement level there) or "value" (the colour field's value),
        as (H, W, 1) float32 with NaN on a miss, and ``Image.array`` its false-colour
        picture as ``--aov`` writes it; ``title``: the title overlay's text (default the
        file's name); ``depth``: also return the float depth (``Image.depth``).

        The GIL is released while the picture renders; Ctrl-C stops it
        (``KeyboardInterrupt``).
        """
        array, depth_array, aov_array, state_json = self._ds.render(
            _native_state(state), _flags(view), threads=threads, aov=aov, title=title, depth=depth
        )
        inputs = [self.path] + [m["path"] for m in json.loads(state_json).get("meshes", [])]
        if isinstance(state, (str, os.PathLike)):
            inputs.append(os.fspath(state))
        return Image(array, ViewState(json.loads(state_json)), depth_array, aov_array, inputs)

    def probe(self, points: Any, *, field: Optional[str] = None) -> Dict[str, np.ndarray]:
        """Every field at ``points`` ((N, 3) world coordinates) as float64 arrays of length
        N (NaN outside the data), plus ``"gradient"`` (N, 3): the gradient of ``field``
        (default ``q``, else the first field), and ``"normal"`` (N, 3): the shading normal;
        the values ``qbricks-view probe --points`` prints."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim == 1:
            pts = pts.reshape(1, -1)
        pts = np.ascontiguousarray(pts)
        return self._ds.probe(pts, field)

    def probe_plane(
        self,
        plane: str,
        *,
        resolution: Union[None, int, str, Tuple[int, int]] = None,
        fields: Union[None, str, Sequence[str]] = None,
    ) -> Dict[str, Any]:
        """Every field (or those named in ``fields``) on a regular grid of a plane, as
        ``qbricks-view probe --plane PLANE --resolution RES`` samples it. ``plane``: the
        CLI's syntax ("OX,OY,OZ:UX,UY,UZ:VX,VY,VZ", or an axis and a value such as "z=0",
        see docs/cli.md); ``resolution``: N (samples along the longer side) or (NU, NV).
        Returns ``{field: (NV, NU) float32 array (NaN outside the data), …, "origin",
        "u", "v" (the resolved patch: a corner and two edges), "outside" (samples outside
        the data)}``; row j, column i is the point origin + (i + 0.5)/NU·u + (j + 0.5)/NV·v."""
        res = None if resolution is None else _flag_value(resolution)
        names = None
        if fields is not None:
            names = fields.split(",") if isinstance(fields, str) else list(fields)
        values, field_names, origin, u, v, outside = self._ds.probe_plane(plane, res, names)
        out: Dict[str, Any] = {name: values[:, :, k] for k, name in enumerate(field_names)}
        out.update(origin=tuple(origin), u=tuple(u), v=tuple(v), outside=outside)
        return out

    def __repr__(self) -> str:
        return f"<qbricks.Dataset {self.path!r} fields={list(self.fields)}>"


def _native_state(state: Any) -> Any:
    """None, a path (str), or the JSON text of a dict as bytes (a str is a path)."""
    if state is None:
        return None
    if isinstance(state, (str, os.PathLike)):
        return os.fspath(state)
    if isinstance(state, ViewState):
        return state.to_json().encode("utf-8")
    if isinstance(state, Mapping):
        return json.dumps(state).encode("utf-8")
    raise TypeError("state: expected a view-state dict or the path of a view-state JSON file")


def open(path: PathLike, *, checksum: bool = True) -> Dataset:  # noqa: A001 (as builtins.open)
    """Opens and validates a ``.qbk`` file. ``checksum=False`` skips the payload checksum
    (faster on huge files; the archive is still validated). Raises ``FileNotFoundError``,
    or :class:`FormatError` for a file that is not a valid ``.qbk`` file."""
    return Dataset(_qbricks.open(os.fspath(path), checksum=checksum))


def bake(
    src: PathLike,
    out: Optional[PathLike] = None,
    *,
    fields: Union[None, str, Sequence[str]] = None,
    grids: Union[None, str, Sequence[str]] = None,
    velocity: Union[None, str, Sequence[str]] = None,
    layout: str = "auto",
    stencil: str = "central",
    max_brick: Optional[int] = None,
    strict: bool = False,
    threads: Optional[int] = None,
    jobs: Optional[int] = None,
    progress: bool = False,
    memory: Union[None, int, str] = None,
) -> Dict[str, Any]:
    """Bakes an OpenVDB file into a ``.qbk`` file, as ``qbricks-bake SRC -o OUT --json``
    does, and returns its summary (cells, bricks, field ranges, ``seconds``, ``output``,
    ``warnings``). ``out`` defaults to ``src`` with the extension ``.qbk``. ``fields``:
    "q", "speed", "vorticity", "lambda2", "helicity", "velocity" or a scalar grid's name
    (a list or a comma-separated string; default q and speed).

    A frame pattern (``"cache/frame_####.vdb"`` or ``%04d``) bakes every frame that exists
    to ``out`` (a pattern too; default the input's with ``.qbk``), ``jobs`` frames at once
    (default: as the threads and memory allow), and writes the manifest
    ``qbricks-view`` reads; the summary is the sequence's (``frames``, ``failed``,
    ``missing``, ``fields``, ``manifest``…). A frame that fails is named in a
    ``ValueError`` once the others are baked.

    ``memory`` is the budget of ``--memory`` (bytes, or ``"64M"``, ``"2G"``…): values go
    to scratch files beside the output as far as it needs, the file is the same, and a
    bake that needs more even so raises ``ValueError`` naming the least budget.

    The GIL is released while baking; Ctrl-C stops the bake between its stages (or
    frames) without writing the output and raises ``KeyboardInterrupt``."""

    def names(v: Union[None, str, Sequence[str]]) -> list:
        if v is None:
            return []
        return [s for s in v.split(",")] if isinstance(v, str) else list(v)

    summary = _qbricks.bake(
        os.fspath(src),
        None if out is None else os.fspath(out),
        fields=None if fields is None else names(fields),
        grids=names(grids),
        velocity=names(velocity),
        layout=layout,
        stencil=stencil,
        max_brick=max_brick,
        strict=strict,
        threads=threads,
        jobs=jobs,
        progress=progress,
        memory=None if memory is None else str(memory),
    )
    return json.loads(summary)
