"""In-memory calibration dataset: frozen dataclasses holding numpy arrays in SI units.

This is what the rest of hostpc uses; the file format (``zerocal-dataset/1``) is handled in
``hostpc.dataset.reading``/``writing`` and ``hostpc.dataset.schema``. Everything here is in
metres, radians
and seconds whatever the file said (see ``docs/conventions.md``). Arrays are copied on
construction and made read-only, so a value cannot change after it was validated.

Shapes use ``N`` for the number of samples, ``n`` for the number of joints (of the arm for
``dual_loop``) and ``n_head`` for the head joints of ``dual_loop``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.json_object import JsonObject

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
StrArray = NDArray[np.str_]

#: a measurement kind's name (the registered kinds: ``hostpc.dataset.kind_registry``)
Method = str


def _frozen(value: ArrayLike, dtype: Any = np.float64) -> NDArray[Any]:
    """Return a read-only copy of ``value`` as an array of ``dtype``."""
    array = np.array(value, dtype=dtype, copy=True)
    array.setflags(write=False)
    return array


def _check_shape(name: str, array: NDArray[Any], shape: tuple[int | None, ...]) -> None:
    """Raise ValueError unless ``array`` has ``shape`` (None matches any length)."""
    if array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape, strict=True)
    ):
        wanted = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {wanted}, got {array.shape}")


def values_equal(a: Any, b: Any) -> bool:
    """Exact equality of dataset values: arrays (NaN equals NaN), mappings, sequences.

    Used by the ``__eq__`` of the dataclasses below, which hold numpy arrays and therefore
    cannot use the dataclass default equality.
    """
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return False
        if a.shape != b.shape or a.dtype.kind != b.dtype.kind:
            return False
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(values_equal(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return (
            type(a) is type(b)
            and len(a) == len(b)
            and all(values_equal(x, y) for x, y in zip(a, b, strict=True))
        )
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return bool(a == b)
    if isinstance(a, float) and isinstance(b, float) and a != a and b != b:
        return True
    return bool(a == b)


def _dataclass_eq(self: Any, other: Any) -> bool:
    """Field-by-field ``values_equal``; values of different types are never equal."""
    if type(other) is not type(self):
        return False
    return all(
        values_equal(getattr(self, f.name), getattr(other, f.name))
        for f in dataclasses.fields(self)
    )


@dataclass(frozen=True, eq=False)
class FramePose:
    """A frame given as position and roll-pitch-yaw, ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Attributes:
        xyz: (3,) origin of the frame in its parent frame, m.
        rpy: (3,) ``[roll, pitch, yaw]``, rad.
    """

    xyz: FloatArray
    rpy: FloatArray

    def __post_init__(self) -> None:
        for name in ("xyz", "rpy"):
            array = _frozen(getattr(self, name))
            _check_shape(f"FramePose.{name}", array, (3,))
            object.__setattr__(self, name, array)

    __eq__ = _dataclass_eq


@dataclass(frozen=True, eq=False)
class SphereFrame:
    """A frame of kind ``"sphere"``: a sphere's centre and radius (sphere_probe's reference
    sphere).

    Attributes:
        center: (3,) sphere centre in the robot base frame, m.
        radius: sphere radius, m.
    """

    center: FloatArray
    radius: float

    def __post_init__(self) -> None:
        center = _frozen(self.center)
        _check_shape("SphereFrame.center", center, (3,))
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "radius", float(self.radius))

    __eq__ = _dataclass_eq


#: a nominal frame's value in a ``Dataset``: a pose, a (3,) point (m), the sphere, named
#: points (name -> (3,) m), or a JSON object kept as the file gave it (the stereo camera
#: model: zerocal reads nothing of it and writes it back unchanged)
Frame = FramePose | FloatArray | SphereFrame | Mapping[str, FloatArray] | JsonObject


@dataclass(frozen=True, eq=False)
class RobotDescription:
    """The robot of a dataset: a built-in robot by name, or an explicit DH/MDH table.

    Exactly one of ``name`` and (``convention``, ``a``, ``alpha``, ``d``, ``theta``) is set.

    Attributes:
        name: built-in robot name (resolve with ``hostpc.kinematics.robots.get_robot``).
        convention: ``"dh"`` or ``"mdh"`` for an explicit table (see conventions.md).
        a, d: (n,) link lengths and offsets, m.
        alpha, theta: (n,) link twists and joint angle offsets, rad.
        mass: (n,) link masses, kg, or None.
        com: (n, 3) link centres of mass, each in its link frame, m, or None.
    """

    name: str | None = None
    convention: Literal["dh", "mdh"] | None = None
    a: FloatArray | None = None
    alpha: FloatArray | None = None
    d: FloatArray | None = None
    theta: FloatArray | None = None
    mass: FloatArray | None = None
    com: FloatArray | None = None
    #: extension A: per-joint "revolute" / "prismatic" of an explicit table (None: revolute)
    joint_types: tuple[str, ...] | None = None
    #: extension A: a URDF robot (absolute path) and its chain's end links
    urdf: str | None = None
    base_link: str | None = None
    tip_link: str | None = None

    def __post_init__(self) -> None:
        explicit = (self.a, self.alpha, self.d, self.theta)
        if self.urdf is not None:
            if self.name is not None or any(v is not None for v in explicit):
                raise ValueError("RobotDescription: a URDF robot has no name or table")
            if not self.base_link or not self.tip_link:
                raise ValueError("RobotDescription: a URDF robot needs base_link and tip_link")
            return
        if self.name is not None:
            if self.convention is not None or any(v is not None for v in explicit):
                raise ValueError("RobotDescription: give a name or an explicit table, not both")
        elif self.convention not in ("dh", "mdh") or any(v is None for v in explicit):
            raise ValueError(
                "RobotDescription: an explicit table needs convention, a, alpha, d and theta"
            )
        n: int | None = None
        for name in ("a", "alpha", "d", "theta", "mass"):
            value = getattr(self, name)
            if value is None:
                continue
            array = _frozen(value)
            _check_shape(f"RobotDescription.{name}", array, (n,))
            n = array.shape[0]
            object.__setattr__(self, name, array)
        if self.com is not None:
            com = _frozen(self.com)
            _check_shape("RobotDescription.com", com, (n, 3))
            object.__setattr__(self, "com", com)

    @property
    def n_joints(self) -> int | None:
        """Joint count of an explicit table; None for a named robot (ask the robot library)."""
        return None if self.a is None else int(self.a.shape[0])

    __eq__ = _dataclass_eq


def _absent() -> FloatArray:
    """Default of an optional per-sample array: empty means "absent for every sample"."""
    return np.empty(0)


@dataclass(frozen=True, eq=False)
class Samples:
    """The samples of a dataset as arrays, one row per sample, SI units.

    Optional per-sample context that a sample did not record is NaN (``group``: -1).
    At construction an empty array (the default) means "absent in every sample".

    Attributes:
        q: (N, n) commanded joint angles, rad. For ``dual_loop`` this is ``q_arm``, the
            joints of the observed arm; if the two arms have different joint counts, the
            rows of the shorter arm are padded with NaN.
        p: (N, 3) measured target point in the sensor (camera) frame, m, or None
            (``sphere_probe``).
        cov: (N, 3, 3) covariance of ``p``, m^2 (a sample given with ``sigma`` holds
            ``sigma**2 * I``), or None.
        sigma: (N,) standard deviation of the contact distance, m (``sphere_probe`` only),
            else None.
        t: (N,) time since the start of the run, s.
        temperature: (N,) temperature, as recorded (no unit conversion).
        speed: (N,) approach speed at contact, m/s.
        approach: (N, n) sign (+1/-1) of the last motion of each joint into the pose.
        group: (N,) probe orientation group (``sphere_probe``), -1 where absent.
        extra: further numeric context by name, each (N,), as recorded.
        uv: (N, 2, 2) pixel centres ``[[uL, vL], [uR, vR]]``, px, or None.
        chain: (N,) ``"left"``/``"right"``: the arm observed (``dual_loop``), else None.
        q_head: (N, n_head) head joint angles, rad (``dual_loop``), else None.
        fields: the fields a measurement kind declares for itself (a plugin's, world_point's
            ``marker``), by name, each with N rows, SI; NaN where an optional one is absent.
    """

    q: FloatArray
    p: FloatArray | None = None
    cov: FloatArray | None = None
    sigma: FloatArray | None = None
    t: FloatArray = field(default_factory=_absent)
    temperature: FloatArray = field(default_factory=_absent)
    speed: FloatArray = field(default_factory=_absent)
    approach: FloatArray = field(default_factory=_absent)
    group: IntArray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    extra: Mapping[str, FloatArray] = field(default_factory=dict)
    uv: FloatArray | None = None
    chain: StrArray | None = None
    q_head: FloatArray | None = None
    fields: Mapping[str, NDArray[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        q = _frozen(self.q)
        _check_shape("Samples.q", q, (None, None))
        object.__setattr__(self, "q", q)
        n_samples, n_joints = q.shape

        def put(name: str, shape: tuple[int | None, ...], dtype: Any = np.float64) -> None:
            value = getattr(self, name)
            if value is None:
                return
            array = _frozen(value, dtype)
            _check_shape(f"Samples.{name}", array, shape)
            object.__setattr__(self, name, array)

        def put_default(name: str, shape: tuple[int, ...], fill: Any, dtype: Any) -> None:
            value = np.asarray(getattr(self, name))
            if value.size == 0:
                value = np.full(shape, fill, dtype=dtype)
            array = _frozen(value, dtype)
            _check_shape(f"Samples.{name}", array, shape)
            object.__setattr__(self, name, array)

        put("p", (n_samples, 3))
        put("cov", (n_samples, 3, 3))
        put("sigma", (n_samples,))
        put("uv", (n_samples, 2, 2))
        put("chain", (n_samples,), np.str_)
        put("q_head", (n_samples, None))
        for name in ("t", "temperature", "speed"):
            put_default(name, (n_samples,), np.nan, np.float64)
        put_default("approach", (n_samples, n_joints), np.nan, np.float64)
        put_default("group", (n_samples,), -1, np.int64)
        extra = {}
        for key, value in self.extra.items():
            array = _frozen(value)
            _check_shape(f"Samples.extra[{key!r}]", array, (n_samples,))
            extra[str(key)] = array
        object.__setattr__(self, "extra", MappingProxyType(extra))
        own = {}
        for key, value in self.fields.items():
            array = np.array(value, copy=True)
            array.setflags(write=False)
            if array.ndim == 0 or array.shape[0] != n_samples:
                raise ValueError(f"Samples.fields[{key!r}]: expected {n_samples} rows, "
                                 f"got shape {array.shape}")
            own[str(key)] = array
        object.__setattr__(self, "fields", MappingProxyType(own))

    @property
    def n(self) -> int:
        """Number of samples ``N`` (same as ``len(samples)``)."""
        return int(self.q.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of columns of ``q`` (joints; for ``dual_loop`` the widest arm)."""
        return int(self.q.shape[1])

    def __len__(self) -> int:
        return self.n

    def subset(self, indices: ArrayLike) -> Samples:
        """The samples at ``indices`` (integer indices or a boolean mask of length N)."""
        index = np.atleast_1d(np.asarray(indices))
        if index.dtype.kind not in "biu":
            raise TypeError("Samples.subset: expected integer indices or a boolean mask")

        def pick(value: Any) -> Any:
            return None if value is None else np.asarray(value)[index]

        return Samples(
            q=self.q[index],
            p=pick(self.p),
            cov=pick(self.cov),
            sigma=pick(self.sigma),
            t=self.t[index],
            temperature=self.temperature[index],
            speed=self.speed[index],
            approach=self.approach[index],
            group=self.group[index],
            extra={k: v[index] for k, v in self.extra.items()},
            uv=pick(self.uv),
            chain=pick(self.chain),
            q_head=pick(self.q_head),
            fields={k: v[index] for k, v in self.fields.items()},
        )

    __eq__ = _dataclass_eq


@dataclass(frozen=True, eq=False)
class KindBlock:
    """A measurement kind's own top-level block of a dataset file (sphere_probe's ``probe``),
    read by the kind's file face (``MeasurementKind.read_block``) and written back with
    ``to_json``. A kind subclasses it with its fields (SI)."""

    def to_json(self) -> JsonObject:
        """The block as the file holds it (SI)."""
        raise NotImplementedError

    def lengths(self) -> Iterable[tuple[str, float]]:
        """(field, value in m) of each length, range-checked on load (default: none)."""
        return ()

    __eq__ = _dataclass_eq


@dataclass(frozen=True, eq=False)
class Dataset:
    """One calibration dataset in SI units (the value of a ``zerocal-dataset/1`` file).

    Attributes:
        method: the measurement kind's name, a built-in's or a plugin's
            (``hostpc.dataset.kind_registry``).
        robot: the robot description.
        frames: nominal frames by name. ``FramePose`` for ``tool`` and, for dual_loop,
            ``camera``, ``left_base``, ``right_base``; a (3,) point (m) for ``target``
            (base frame) and, for dual_loop, ``left_target``/``right_target`` (flange
            frames); ``SphereFrame`` for ``sphere``; for stereo_target the stereo camera
            model ``camera`` is kept as the plain dict of the file.
        samples: the samples.
        known: names of frames held fixed in the fit.
        blocks: the kind's own top-level blocks by field name (``KindBlock``; sphere_probe's
            ``probe``, the stylus radius: ``hostpc.kinds.sphere_probe.file_face``).
        extra_fields: unknown top-level fields of the file, kept for a round trip.
    """

    method: Method
    robot: RobotDescription
    frames: Mapping[str, Frame]
    samples: Samples
    known: tuple[str, ...] = ()
    blocks: Mapping[str, KindBlock] = field(default_factory=dict)
    extra_fields: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.method, str) or not self.method.isidentifier():
            raise ValueError(f"Dataset.method: not a method name: {self.method!r}")
        frames: dict[str, Frame] = {}
        for name, value in self.frames.items():
            if isinstance(value, FramePose | SphereFrame | Mapping):
                frames[name] = value
            else:
                point = _frozen(value)
                _check_shape(f"Dataset.frames[{name!r}]", point, (3,))
                frames[name] = point
        object.__setattr__(self, "frames", MappingProxyType(frames))
        object.__setattr__(self, "known", tuple(self.known))
        object.__setattr__(self, "blocks", MappingProxyType(dict(self.blocks)))
        object.__setattr__(self, "extra_fields", MappingProxyType(dict(self.extra_fields)))

    @property
    def n_samples(self) -> int:
        """Number of samples ``N``."""
        return self.samples.n

    @property
    def n_joints(self) -> int:
        """Joint count ``n`` (width of ``samples.q``; for dual_loop the widest arm)."""
        return self.samples.n_joints

    def pose(self, name: str) -> FramePose:
        """The frame ``name`` as a ``FramePose`` (``tool``, ``camera``, ``left_base``, ...)."""
        value = self.frames[name]
        if not isinstance(value, FramePose):
            raise TypeError(f"frames[{name!r}] is not a pose: {type(value).__name__}")
        return value

    def point(self, name: str) -> FloatArray:
        """The frame ``name`` as a (3,) point, m (``target``, ``left_target``, ...)."""
        value = self.frames[name]
        if not isinstance(value, np.ndarray):
            raise TypeError(f"frames[{name!r}] is not a point: {type(value).__name__}")
        return value

    def with_samples(self, samples: Samples) -> Dataset:
        """A copy of this dataset with other samples (e.g. a cross-validation fold)."""
        return dataclasses.replace(self, samples=samples)

    __eq__ = _dataclass_eq
