"""Type stubs for the compiled module itaipu_calib._core (see itaipu_calib for the docs)."""

import os
from pathlib import Path
from typing import Any, Dict, Iterable, List, Literal, Mapping, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

_Array = npt.NDArray[np.float64]
_PathLike = Union[str, "os.PathLike[str]"]

class ItaipuError(Exception):
    kind: Optional[str]

class EventError(ItaipuError): ...
class UnitModelError(ItaipuError): ...
class InitError(ItaipuError): ...
class SimulationError(ItaipuError): ...
class CalibrationError(ItaipuError): ...

class Event:
    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def system_mva(self) -> float: ...
    @property
    def nominal_hz(self) -> float: ...
    @property
    def toml_path(self) -> Optional[Path]: ...
    @property
    def csv_path(self) -> Path: ...
    @property
    def playback(self) -> Tuple[float, float]: ...
    @property
    def init(self) -> Tuple[float, float]: ...
    @property
    def fit(self) -> Tuple[float, float]: ...
    @property
    def time_s(self) -> _Array: ...
    @property
    def v_mag_pu(self) -> _Array: ...
    @property
    def v_ang_rad(self) -> _Array: ...
    @property
    def p_pu(self) -> _Array: ...
    @property
    def q_pu(self) -> _Array: ...
    @property
    def freq_hz(self) -> Optional[_Array]: ...
    @property
    def efd_pu(self) -> Optional[_Array]: ...
    @property
    def ifd_pu(self) -> Optional[_Array]: ...
    def operating_point(self) -> Dict[str, Any]: ...
    def __len__(self) -> int: ...

class Unit:
    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def machine_mva(self) -> float: ...
    @property
    def nominal_hz(self) -> float: ...
    @property
    def path(self) -> Optional[Path]: ...
    def parameters(self) -> Dict[str, float]: ...
    def models(self) -> List[str]: ...
    def blocks(self) -> Dict[str, str]: ...
    def to_toml(self) -> str: ...

class Traces:
    @property
    def time_s(self) -> _Array: ...
    @property
    def columns(self) -> List[str]: ...
    @property
    def stats(self) -> Dict[str, int]: ...
    def to_dict(self) -> Dict[str, _Array]: ...
    def __getitem__(self, name: str) -> _Array: ...
    def __getattr__(self, name: str) -> _Array: ...
    def __contains__(self, name: object) -> bool: ...
    def __len__(self) -> int: ...

class FitResult:
    @property
    def report(self) -> Dict[str, Any]: ...
    @property
    def unit(self) -> Unit: ...
    @property
    def stages(self) -> List[str]: ...
    @property
    def fitness(self) -> List[Tuple[str, float]]: ...
    def parameters(self, stage: str) -> Dict[str, float]: ...
    def traces(self, stage: str, event: Optional[str] = None) -> Tuple[Traces, Traces]: ...

class Diagnosis:
    @property
    def verdict(self) -> Dict[str, Any]: ...
    @property
    def cause(self) -> str: ...
    @property
    def candidates(self) -> List[Dict[str, Any]]: ...
    @property
    def evidence(self) -> List[Dict[str, Any]]: ...
    @property
    def report(self) -> Dict[str, Any]: ...
    @property
    def extended_unit_toml(self) -> Optional[str]: ...
    @property
    def extended_unit(self) -> Optional[Unit]: ...
    @property
    def traces_before(self) -> Dict[str, Dict[str, _Array]]: ...
    @property
    def traces_after(self) -> Dict[str, Dict[str, _Array]]: ...
    def to_json(self) -> str: ...

_Events = Union[_PathLike, Event, Iterable[Union[_PathLike, Event]]]
_Hide = Union[
    Mapping[str, Optional[Mapping[str, float]]],
    Sequence[Union[str, Tuple[str, Optional[Mapping[str, float]]]]],
]

def load_event(path: _PathLike) -> Event: ...
def load_unit(path: _PathLike) -> Unit: ...
def check(
    event: Union[_PathLike, Event], unit: Optional[Union[_PathLike, Unit]] = None
) -> List[Dict[str, Any]]: ...
def read_dyr(
    path: _PathLike,
    *,
    bus: Optional[int] = None,
    id: Optional[str] = None,
    bases: Optional[_PathLike] = None,
    mbase: Optional[float] = None,
    nominal_hz: Optional[float] = None,
    zr: Optional[float] = None,
    zx: Optional[float] = None,
) -> Unit: ...
def write_dyr(unit: Unit, path: _PathLike, *, bus: int = 1, id: str = "1") -> List[str]: ...
def import_pmu(
    path: _PathLike,
    system_mva: float,
    nominal_hz: float,
    *,
    v_base_kv: Optional[float] = None,
    pu_base_mva: Optional[float] = None,
    line_voltage: bool = False,
    current_into_machine: bool = False,
    rate: Optional[float] = None,
    map: Optional[Dict[str, str]] = None,
    name: Optional[str] = None,
    out: Optional[_PathLike] = None,
) -> Tuple[Event, Dict[str, Any]]: ...
def simulate(
    event: Union[_PathLike, Event],
    unit: Union[_PathLike, Unit],
    *,
    method: str = "dopri5",
    rtol: float = 1e-6,
    atol: float = 1e-7,
    step: float = 0.001,
) -> Traces: ...
def fit(
    events: _Events,
    unit: Union[_PathLike, Unit],
    *,
    calib: Optional[_PathLike] = None,
    stages: Union[str, Sequence[str], None] = "all",
    strategy: Optional[str] = None,
    seed: Optional[int] = None,
    particles: Optional[int] = None,
    pso_iterations: Optional[int] = None,
    lbfgs_iterations: Optional[int] = None,
    polish: bool = True,
    held_out: Optional[_Events] = (),
) -> FitResult: ...
def models() -> List[Dict[str, Any]]: ...
def causes() -> List[Dict[str, Any]]: ...

@overload
def synth(
    unit: Union[_PathLike, Unit],
    *,
    kind: str = "dip",
    duration: float = 20.0,
    rate: float = 60.0,
    system_mva: Optional[float] = None,
    pq_sigma: float = 0.002,
    v_sigma: float = 0.0005,
    quantum: float = 0.0014,
    skew_ms: float = 0.0,
    seed: int = 1,
    name: Optional[str] = None,
    hide: Optional[_Hide] = None,
    return_truth: Literal[False] = False,
) -> Event: ...
@overload
def synth(
    unit: Union[_PathLike, Unit],
    *,
    kind: str = "dip",
    duration: float = 20.0,
    rate: float = 60.0,
    system_mva: Optional[float] = None,
    pq_sigma: float = 0.002,
    v_sigma: float = 0.0005,
    quantum: float = 0.0014,
    skew_ms: float = 0.0,
    seed: int = 1,
    name: Optional[str] = None,
    hide: Optional[_Hide] = None,
    return_truth: Literal[True],
) -> Tuple[Event, Unit]: ...
def diagnose(
    unit: Union[_PathLike, Unit],
    events: _Events,
    held_out: Optional[_Events] = None,
    *,
    causes: Union[str, Sequence[str], None] = None,
    seed: int = 1,
    particles: int = 16,
    pso_iterations: int = 20,
    lbfgs_iterations: int = 15,
    threads: Optional[int] = None,
    refit: Union[str, Sequence[str], Mapping[str, Tuple[float, float]], None] = None,
    fit: Optional[FitResult] = None,
    user_causes: Union[_PathLike, Sequence[_PathLike], None] = None,
) -> Diagnosis: ...
