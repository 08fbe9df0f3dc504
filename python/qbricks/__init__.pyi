# Type stubs of the qbricks package (see __init__.py for the documentation).
import os
from collections.abc import MutableMapping
from typing import Any, Dict, Iterator, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
PathLike = Union[str, os.PathLike[str]]
State = Union[None, PathLike, "ViewState", Mapping[str, Any]]
Vec3 = Union[Sequence[float], npt.NDArray[np.floating[Any]]]
Plane = Union[str, Tuple[Vec3, Vec3]]

class FormatError(ValueError):
    """A file that is not a valid .qbk brick file (the CLI's one-line message)."""

class ViewState(MutableMapping[str, Any]):
    """A view state, as --save-state writes it; every change is checked."""
    width: int
    height: int
    mode: str
    iso: float
    iso_field: str
    spp: int
    camera: Dict[str, Any]
    colormap: Dict[str, Any]
    def __init__(self, state: Union[Mapping[str, Any], "ViewState"]) -> None: ...
    @classmethod
    def from_json(cls, text: str) -> "ViewState": ...
    @classmethod
    def load(cls, path: PathLike) -> "ViewState": ...
    def to_json(self) -> str: ...
    def to_dict(self) -> Dict[str, Any]: ...
    def save(self, path: PathLike) -> None: ...
    def replace(self, **changes: Any) -> "ViewState": ...
    def __getitem__(self, key: str) -> Any: ...
    def __setitem__(self, key: str, value: Any) -> None: ...
    def __delitem__(self, key: str) -> None: ...
    def __iter__(self) -> Iterator[str]: ...
    def __len__(self) -> int: ...
    def __getattr__(self, key: str) -> Any: ...

class Image:
    array: npt.NDArray[np.uint8]
    state: ViewState
    depth: Optional[npt.NDArray[np.float32]]
    aov: Optional[npt.NDArray[np.float32]]
    @property
    def shape(self) -> Tuple[int, ...]: ...
    def __array__(self, dtype: Any = ..., copy: Any = ...) -> np.ndarray: ...
    def to_png(self) -> bytes: ...
    def _repr_png_(self) -> bytes: ...
    def save(self, path: PathLike) -> None: ...

class Dataset:
    @property
    def path(self) -> str: ...
    @property
    def fields(self) -> Dict[str, Tuple[float, float]]: ...
    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]: ...
    @property
    def levels(self) -> list[Dict[str, Any]]: ...
    def info(self) -> Dict[str, Any]: ...
    def histogram(self, field: str) -> Tuple[npt.NDArray[np.uint64], npt.NDArray[np.float64]]: ...
    def state(self, state: State = ..., **view: Any) -> ViewState: ...
    def render(
        self,
        state: State = ...,
        *,
        threads: Optional[int] = ...,
        aov: Optional[str] = ...,
        title: Optional[str] = ...,
        depth: bool = ...,
        width: Optional[int] = ...,
        height: Optional[int] = ...,
        mode: Optional[str] = ...,
        iso: Union[None, float, Sequence[float]] = ...,
        iso_field: Optional[str] = ...,
        iso_opacity: Union[None, float, Sequence[float]] = ...,
        iso_colour: Union[None, str, Sequence[str]] = ...,
        strategy: Optional[str] = ...,
        step: Optional[float] = ...,
        spp: Optional[int] = ...,
        eye: Optional[Vec3] = ...,
        look_at: Optional[Vec3] = ...,
        up: Optional[Vec3] = ...,
        fov: Optional[float] = ...,
        ortho: Optional[float] = ...,
        colour_field: Optional[str] = ...,
        colormap: Optional[str] = ...,
        colour_range: Union[None, str, Tuple[float, float]] = ...,
        colour_centre: Optional[float] = ...,
        log: bool = ...,
        overlays: Union[None, str, Sequence[str]] = ...,
        clip: Optional[Sequence[Plane]] = ...,
        slices: Optional[Sequence[Plane]] = ...,
        slice_opacity: Optional[float] = ...,
        slice_contours: bool = ...,
        slice_clip: bool = ...,
        shadows: bool = ...,
        preintegrated: bool = ...,
        no_preintegrated: bool = ...,
        meshes: Optional[Sequence[str]] = ...,
    ) -> Image: ...
    def probe(self, points: npt.ArrayLike, *, field: Optional[str] = ...) -> Dict[str, npt.NDArray[np.float64]]: ...

    def probe_plane(
        self,
        plane: str,
        *,
        resolution: Union[None, int, str, Tuple[int, int]] = ...,
        fields: Union[None, str, Sequence[str]] = ...,
    ) -> Dict[str, Any]: ...

def open(path: PathLike, *, checksum: bool = ...) -> Dataset: ...
def bake(
    src: PathLike,
    out: Optional[PathLike] = ...,
    *,
    fields: Union[None, str, Sequence[str]] = ...,
    grids: Union[None, str, Sequence[str]] = ...,
    velocity: Union[None, str, Sequence[str]] = ...,
    layout: str = ...,
    stencil: str = ...,
    max_brick: Optional[int] = ...,
    strict: bool = ...,
    threads: Optional[int] = ...,
    jobs: Optional[int] = ...,
    progress: bool = ...,
    memory: Union[None, int, str] = ...,
) -> Dict[str, Any]: ...
