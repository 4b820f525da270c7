"""Co-simulate a belt-drive FMU (ours or a third party's, FMI 2.0 or 3.0) from the twin.

The wrapper reads the model description once, resolves value references by name once,
instantiates once, and then runs a tight (set inputs, doStep, get outputs) loop through the
FMU's C functions with pre-built ctypes arrays, because the twin steps it at 240 Hz.

Example::

    with BeltDrive() as drive:
        state = drive.step(1 / 240, setpoint_mps=0.5, load_mass_kg=20.0)
"""

from __future__ import annotations

import ctypes
import math
import numbers
import shutil
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from interfaces.cell import MAX_DRIVE_STEP_S, DriveMapping
from interfaces.errors import cut
from twin.errors import FmuError

_FLOAT_TYPES = {"Real", "Float64"}
_INT_TYPES = {"Integer", "Int32"}
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
"""Range of an FMI ``Int32`` (FMI 3) / ``Integer`` (FMI 2, a C ``int``) variable."""

MAX_STEP_S = MAX_DRIVE_STEP_S
"""Longest communication step :meth:`BeltDrive.step` accepts, in seconds.

The inputs are held constant over a step and the FMU integrates it with its own fixed internal
step (1 ms for ours), so a step costs ``dt / internal step`` integrations and hides every
setpoint and load change inside it. The twin steps at 1/240 s; a step longer than 1 s is longer
than any dynamics of the cell (the PI speed loop settles in about 0.1 s, an object crosses the
workspace in 1 to 2 s) and is a caller's mistake (milliseconds passed as seconds, a corrupt time
stamp). Refusing it also bounds one call's cost: 1 s is 1000 internal steps of ours, well under
a millisecond, where a step of a day would block the process for 86 million.
"""


def _as_float(value: object) -> float | None:
    """``value`` as a float when it is a real number other than a bool, else None."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except (OverflowError, ValueError):
        return None


def _as_int(value: object) -> int | None:
    """``value`` as an int when it is an integer (or an integral float), not a bool, else None."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    if isinstance(value, numbers.Integral):
        return int(value)
    number = _as_float(value)
    if number is None or not number.is_integer():
        return None
    return int(number)


_SHOWN = 500
"""The most characters of a refused value an error quotes."""

_NOT_A_NUMBER = "needs a real number (not a bool or a string)"
_FINITE = "needs a finite number"


@dataclass(frozen=True, slots=True)
class BeltState:
    """Belt-drive outputs at one communication point.

    ``motor_torque_Nm`` and ``motor_current_A`` are NaN when the FMU's mapping has none.
    """

    time_s: float
    belt_speed_mps: float
    belt_position_m: float
    motor_torque_Nm: float
    motor_current_A: float


VariableMapping = DriveMapping
"""Names of the FMU variables that play each role (a cell's ``drive.mapping``); the defaults are
our BeltDrive FMU's."""


@dataclass(frozen=True)
class FmuPlan:
    """What the wrapper needs of an FMU file before it instantiates it: its model description,
    FMI version, the value references of the mapped inputs and outputs (in the order the
    wrapper binds them) and the parameters' value references with their checked values."""

    description: Any
    fmi_version: int
    inputs: tuple[int, ...]
    outputs: tuple[int, ...]
    float_parameters: tuple[tuple[int, float], ...]
    int_parameters: tuple[tuple[int, int], ...]


def _fail(path: Path, what: str) -> FmuError:
    return FmuError(f"{path}: {what}")


def _resolve(path: Path, variables: Mapping[str, Any], field: str, name: str) -> int:
    variable = variables.get(name)
    if variable is None:
        raise _fail(
            path, f"mapping field {field!r} names variable {cut(name)}, which the FMU lacks"
        )
    if variable.type not in _FLOAT_TYPES:
        raise _fail(path, f"mapped variable {cut(name)} ({field}) is {variable.type}, not Real")
    return int(variable.valueReference)


def _float_parameter(path: Path, name: str, value: object) -> float:
    number = _as_float(value)
    if number is None or not math.isfinite(number):
        what = _NOT_A_NUMBER if number is None else _FINITE
        raise _fail(
            path, f"parameter {cut(name)} = {cut(value, _SHOWN)} is invalid: Float64 {what}"
        )
    return number


def _int_parameter(path: Path, name: str, value: object) -> int:
    number = _as_int(value)
    if number is None:
        raise _fail(
            path, f"parameter {cut(name)} = {cut(value, _SHOWN)} is invalid: Int32 needs an integer"
        )
    if not INT32_MIN <= number <= INT32_MAX:
        raise _fail(
            path,
            f"parameter {cut(name)} = {cut(value, _SHOWN)} is invalid: outside the Int32 range "
            f"[{INT32_MIN}, {INT32_MAX}]",
        )
    return number


def read_description(path: Path) -> Any:
    """The model description of the FMU file ``path`` (fmpy's), checked to be FMI 2.0 or 3.0
    co-simulation; :class:`FmuError` naming the file when it is missing, not a zip archive, has
    no readable ``modelDescription.xml``, or is of another kind."""
    from fmpy import read_model_description

    if not path.is_file():
        raise _fail(path, "FMU file not found (build ours with `cdw-twin fmu build`)")
    if not zipfile.is_zipfile(path):
        raise _fail(path, "not a valid FMU: not a zip archive")
    try:
        description = read_model_description(str(path))
    except Exception as exc:
        raise _fail(path, f"not a valid FMU: {cut(str(exc), 300)}") from exc
    if description.fmiVersion not in {"2.0", "3.0"}:
        raise _fail(path, f"FMI version {cut(description.fmiVersion)} is not supported (2.0, 3.0)")
    if description.coSimulation is None:
        raise _fail(path, "the FMU does not support co-simulation")
    return description


def plan_fmu(path: Path, mapping: VariableMapping, parameters: Mapping[str, object]) -> FmuPlan:
    """Read and check the FMU ``path`` against ``mapping`` and ``parameters`` without
    instantiating it (cheap: the model description only), so a cell's drive can be checked
    before anything starts. :class:`FmuError` names the file and the variable: a mapped
    variable the FMU lacks or that is not Real, a parameter it lacks, of a type the wrapper
    cannot set, or whose value does not fit its type."""
    description = read_description(path)
    variables = {v.name: v for v in description.modelVariables}
    inputs = [_resolve(path, variables, "speed_setpoint", mapping.speed_setpoint)]
    if mapping.load_mass is not None:
        inputs.append(_resolve(path, variables, "load_mass", mapping.load_mass))
    outputs = [
        _resolve(path, variables, "belt_speed", mapping.belt_speed),
        _resolve(path, variables, "belt_position", mapping.belt_position),
    ]
    if mapping.motor_torque is not None:
        outputs.append(_resolve(path, variables, "motor_torque", mapping.motor_torque))
    if mapping.motor_current is not None:
        outputs.append(_resolve(path, variables, "motor_current", mapping.motor_current))
    floats: list[tuple[int, float]] = []
    ints: list[tuple[int, int]] = []
    for name, value in parameters.items():
        variable = variables.get(name)
        if variable is None:
            raise _fail(path, f"parameter {cut(name)} is not a variable of the FMU")
        if variable.type in _FLOAT_TYPES:
            floats.append((variable.valueReference, _float_parameter(path, name, value)))
        elif variable.type in _INT_TYPES:
            ints.append((variable.valueReference, _int_parameter(path, name, value)))
        else:
            raise _fail(
                path,
                f"parameter {cut(name)} is of type {variable.type}, which the wrapper cannot set "
                "(only Float64/Real and Int32/Integer)",
            )
    return FmuPlan(
        description=description,
        fmi_version=int(description.fmiVersion[0]),
        inputs=tuple(inputs),
        outputs=tuple(outputs),
        float_parameters=tuple(floats),
        int_parameters=tuple(ints),
    )


class BeltDrive:
    """A belt-drive FMU instantiated once and stepped by the twin.

    ``fmu_path`` defaults to the built ``fmus/build/BeltDrive.fmu``. ``parameters`` are set by
    variable name before initialisation. Raises :class:`twin.errors.FmuError` naming the file and
    the variable for a missing or malformed FMU, an unknown mapped or parameter variable, or an
    FMU call that returns an error (with the FMU's logged message).

    Values are checked by the wrapper before they reach the FMU, per variable type, because a
    third party's FMU need not check them and a C call converts silently:

    - ``Float64`` / ``Real`` parameters and inputs (and ``start_time_s``): a real number (int,
      float, numpy scalar), not a bool or a string, and finite. FMI allows NaN and infinity in
      a Float64, but no quantity of a belt drive can be one, and an unchecked NaN would be
      integrated into the belt speed the twin moves its objects with.
    - ``Int32`` / ``Integer`` parameters: an integer (or an integral float), not a bool, within
      ``[INT32_MIN, INT32_MAX]``; outside it the C call would wrap it silently.
    - Parameters of any other type cannot be set through the wrapper.

    :meth:`step` takes ``0 < dt_s <= MAX_STEP_S``. A refused value raises FmuError naming the
    variable and the value, and leaves the FMU untouched: the next good call proceeds as if the
    bad one never happened.
    """

    def __init__(
        self,
        fmu_path: Path | None = None,
        *,
        mapping: VariableMapping | None = None,
        parameters: Mapping[str, float] | None = None,
        start_time_s: float = 0.0,
    ) -> None:
        """Open, instantiate and initialise the FMU."""
        from fmus.build import default_fmu_path

        self.path = Path(fmu_path) if fmu_path is not None else default_fmu_path(3)
        self.mapping = mapping if mapping is not None else VariableMapping()
        self.messages: list[str] = []
        self._unzip_dir: str | None = None
        self._slave: Any = None
        self._initialized = False
        self._closed = False
        start = _as_float(start_time_s)
        if start is None or not math.isfinite(start):
            msg = f"{self.path}: start_time_s = {start_time_s!r} is invalid: {_FINITE}"
            raise FmuError(msg)
        self._time_s = start
        try:
            self._open(parameters or {})
        except BaseException:
            self.close()
            raise

    def _open(self, parameters: Mapping[str, float]) -> None:
        from fmpy import extract

        plan = plan_fmu(self.path, self.mapping, parameters)
        self.fmi_version = plan.fmi_version
        self._has_torque = self.mapping.motor_torque is not None
        self._has_current = self.mapping.motor_current is not None
        self._unzip_dir = extract(str(self.path))
        self._instantiate(plan.description)
        self._bind(list(plan.inputs), list(plan.outputs))
        self._initialize(list(plan.float_parameters), list(plan.int_parameters))

    def _input(self, name: str, value: object) -> float:
        """A refused-or-converted input value (the slow path of :meth:`step`)."""
        number = _as_float(value)
        if number is None or not math.isfinite(number):
            what = _NOT_A_NUMBER if number is None else _FINITE
            msg = f"{self.path}: input {name} = {cut(value, _SHOWN)} is invalid: Float64 {what}"
            raise FmuError(msg)
        return number

    def _step_size(self, dt_s: object) -> float:
        """A refused-or-converted step size (the slow path of :meth:`step`)."""
        number = _as_float(dt_s)
        if number is None or not 0.0 < number <= MAX_STEP_S:
            msg = (
                f"{self.path}: step dt_s = {cut(dt_s)} is invalid: needs a number in "
                f"(0, {MAX_STEP_S}] s (MAX_STEP_S)"
            )
            raise FmuError(msg)
        return number

    def _log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        text = (message or b"").decode("utf-8", "replace")
        self.messages.append(text)
        del status, category

    def _instantiate(self, description: Any) -> None:
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        common = {
            "guid": description.guid,
            "unzipDirectory": self._unzip_dir,
            "modelIdentifier": description.coSimulation.modelIdentifier,
            "instanceName": "belt_drive",
        }
        try:
            if self.fmi_version == 3:
                self._slave = FMU3Slave(**common)
                self._slave.instantiate(
                    logMessage=lambda env, status, cat, msg: self._log(status, cat, msg)
                )
            else:
                self._slave = FMU2Slave(**common)
                self._slave.instantiate(callbacks=self._fmi2_callbacks())
        except Exception as exc:
            msg = f"{self.path}: instantiation failed: {exc}{self._last_message()}"
            raise FmuError(msg) from exc

    def _fmi2_callbacks(self) -> Any:
        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, name, status, cat, msg: self._log(status, cat, msg)
        )
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(ctypes.byref(callbacks))
        except Exception:
            pass
        self._callbacks = callbacks
        return callbacks

    def _bind(self, inputs: list[int], outputs: list[int]) -> None:
        dll = self._slave.dll
        prefix = f"fmi{self.fmi_version}"
        self._instance = self._slave.component
        self._n_in = len(inputs)
        self._n_out = len(outputs)
        self._in_vrs = (ctypes.c_uint32 * self._n_in)(*inputs)
        self._in_values = (ctypes.c_double * self._n_in)()
        self._out_vrs = (ctypes.c_uint32 * self._n_out)(*outputs)
        self._out_values = (ctypes.c_double * self._n_out)()
        real = "Float64" if self.fmi_version == 3 else "Real"
        self._set_real: Callable[..., int] = getattr(dll, f"{prefix}Set{real}")
        self._get_real: Callable[..., int] = getattr(dll, f"{prefix}Get{real}")
        self._do_step_fn: Callable[..., int] = getattr(dll, f"{prefix}DoStep")
        if self.fmi_version == 3:
            flags = [ctypes.c_bool() for _ in range(3)]
            self._last_time = ctypes.c_double()
            self._step_tail: tuple[Any, ...] = (
                True, *(ctypes.byref(f) for f in flags), ctypes.byref(self._last_time),
            )  # fmt: skip
            self._step_flags = flags
        else:
            self._step_tail = (True,)

    def _check(self, status: int, what: str) -> None:
        if status > 1:
            msg = f"{self.path}: {what} returned status {status}{self._last_message()}"
            raise FmuError(msg)

    def _last_message(self) -> str:
        return f": {self.messages[-1]}" if self.messages else ""

    def _initialize(self, floats: list[tuple[int, float]], ints: list[tuple[int, int]]) -> None:
        from fmpy.fmi1 import FMICallException

        slave = self._slave
        try:
            if self.fmi_version == 3:
                slave.enterInitializationMode(startTime=self._time_s)
            else:
                slave.setupExperiment(startTime=self._time_s)
                slave.enterInitializationMode()
            set_float = slave.setFloat64 if self.fmi_version == 3 else slave.setReal
            set_int = slave.setInt32 if self.fmi_version == 3 else slave.setInteger
            if floats:
                set_float([vr for vr, _ in floats], [v for _, v in floats])
            if ints:
                set_int([vr for vr, _ in ints], [v for _, v in ints])
            slave.exitInitializationMode()
        except FMICallException as exc:
            msg = f"{self.path}: initialisation failed: {exc}{self._last_message()}"
            raise FmuError(msg) from exc
        self._initialized = True
        self._check(
            self._get_real(self._instance, self._out_vrs, self._n_out, self._out_values,
                           *self._size_arg(self._n_out)),
            "get outputs",
        )  # fmt: skip
        self._state = self._make_state()

    def _size_arg(self, n: int) -> tuple[int, ...]:
        return (n,) if self.fmi_version == 3 else ()

    def _make_state(self) -> BeltState:
        values = self._out_values
        i = 2
        torque = current = math.nan
        if self._has_torque:
            torque = values[i]
            i += 1
        if self._has_current:
            current = values[i]
        return BeltState(
            time_s=self._time_s,
            belt_speed_mps=values[0],
            belt_position_m=values[1],
            motor_torque_Nm=torque,
            motor_current_A=current,
        )

    @property
    def state(self) -> BeltState:
        """Outputs at the latest communication point."""
        return self._state

    def step(self, dt_s: float, setpoint_mps: float, load_mass_kg: float) -> BeltState:
        """Hold the inputs over ``dt_s`` seconds, advance the FMU and return its outputs.

        ``0 < dt_s <= MAX_STEP_S``; the inputs are finite numbers (see the class docstring).
        """
        if self._closed:
            msg = f"{self.path}: step() called after close()"
            raise FmuError(msg)
        if not (type(dt_s) is float and 0.0 < dt_s <= MAX_STEP_S):
            dt_s = self._step_size(dt_s)
        if not (type(setpoint_mps) is float and math.isfinite(setpoint_mps)):
            setpoint_mps = self._input(self.mapping.speed_setpoint, setpoint_mps)
        if self._n_in > 1 and not (type(load_mass_kg) is float and math.isfinite(load_mass_kg)):
            load_mass_kg = self._input(str(self.mapping.load_mass), load_mass_kg)
        values = self._in_values
        values[0] = setpoint_mps
        if self._n_in > 1:
            values[1] = load_mass_kg
        instance = self._instance
        if self.fmi_version == 3:
            status = self._set_real(instance, self._in_vrs, self._n_in, values, self._n_in)
        else:
            status = self._set_real(instance, self._in_vrs, self._n_in, values)
        if status > 1:
            self._check(status, f"set inputs (setpoint_mps={setpoint_mps}, load={load_mass_kg})")
        status = self._do_step_fn(instance, self._time_s, dt_s, *self._step_tail)
        if status > 1:
            self._check(status, f"doStep(t={self._time_s}, dt={dt_s})")
        self._time_s += dt_s
        if self.fmi_version == 3:
            status = self._get_real(instance, self._out_vrs, self._n_out, self._out_values,
                                    self._n_out)  # fmt: skip
        else:
            status = self._get_real(instance, self._out_vrs, self._n_out, self._out_values)
        if status > 1:
            self._check(status, "get outputs")
        self._state = self._make_state()
        return self._state

    def close(self) -> None:
        """Terminate and free the FMU instance and delete its extracted files (idempotent)."""
        if self._closed:
            return
        self._closed = True
        slave = self._slave
        if slave is not None:
            try:
                if self._initialized:
                    slave.terminate()
            except Exception:
                pass
            slave.freeInstance()
        if self._unzip_dir is not None:
            shutil.rmtree(self._unzip_dir, ignore_errors=True)

    def __enter__(self) -> Self:
        """Return the initialised drive."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        """Close the drive."""
        self.close()
