"""Bad input through fmpy: error status, a logged message naming the value, the host survives."""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from twin.belt_drive import BeltDrive, VariableMapping
from twin.errors import FmuError


class Session:
    """A real fmpy slave with a collecting logger."""

    def __init__(self, fmu: Path, version: int) -> None:
        self.messages: list[str] = []
        md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.version = version
        kwargs = {
            "guid": md.guid,
            "unzipDirectory": extract(str(fmu)),
            "modelIdentifier": md.coSimulation.modelIdentifier,
            "instanceName": "bad",
        }
        if version == 3:
            self.slave = FMU3Slave(**kwargs)
            self.slave.instantiate(
                logMessage=lambda _env, _st, _cat, msg: self.messages.append(msg.decode())
            )
        else:
            from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(
                lambda _env, _name, _st, _cat, msg: self.messages.append(msg.decode())
            )
            self.slave = FMU2Slave(**kwargs)
            self.slave.instantiate(callbacks=self.callbacks)

    def set(self, name: str, value: float) -> None:
        vr = [self.vr[name]]
        if name == "perturbation_seed":
            (self.slave.setInt32 if self.version == 3 else self.slave.setInteger)(vr, [int(value)])
        else:
            (self.slave.setFloat64 if self.version == 3 else self.slave.setReal)(vr, [value])

    def enter_init(self) -> None:
        if self.version == 3:
            self.slave.enterInitializationMode()
        else:
            self.slave.setupExperiment(startTime=0.0)
            self.slave.enterInitializationMode()


BAD_PARAMETERS = [
    ("drum_radius_m", 0.0), ("drum_radius_m", -0.1), ("motor_inertia_kgm2", 0.0),
    ("drum_inertia_kgm2", -1.0), ("belt_mass_kg", 0.0), ("speed_gain_Aspm", -1.0),
    ("integral_gain_Apm", -5.0), ("current_limit_A", math.nan), ("internal_step_s", 0.002),
    ("perturbation_std_N", -1.0), ("perturbation_seed", -3), ("setpoint_weight", 1.5),
    ("setpoint_weight", -0.1), ("standstill_speed_mps", 0.0),
]  # fmt: skip


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize(("name", "value"), BAD_PARAMETERS)
def test_invalid_parameter_is_rejected_and_logged(
    fmus: dict[int, Path], version: int, name: str, value: float
) -> None:
    session = Session(fmus[version], version)
    with pytest.raises(FMICallException, match="status 3"):
        session.set(name, value)
    assert any(name in m and "invalid" in m for m in session.messages)
    session.enter_init()
    session.slave.exitInitializationMode()
    session.slave.terminate()
    session.slave.freeInstance()


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize(("name", "value"),
                         [("speed_setpoint_mps", math.nan), ("speed_setpoint_mps", math.inf),
                          ("speed_setpoint_mps", -0.2), ("load_mass_kg", -math.inf),
                          ("load_mass_kg", -2.0)])  # fmt: skip
def test_invalid_input_is_rejected_and_logged(
    fmus: dict[int, Path], version: int, name: str, value: float
) -> None:
    session = Session(fmus[version], version)
    session.enter_init()
    session.slave.exitInitializationMode()
    with pytest.raises(FMICallException, match="status 3"):
        session.set(name, value)
    assert any(name in m for m in session.messages)
    session.slave.doStep(0.0, 0.01)
    session.slave.terminate()
    session.slave.freeInstance()


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize("step_s", [0.0, -0.01, math.nan])
def test_non_positive_step_is_rejected_and_logged(
    fmus: dict[int, Path], version: int, step_s: float
) -> None:
    session = Session(fmus[version], version)
    session.enter_init()
    session.slave.exitInitializationMode()
    with pytest.raises(FMICallException, match="status 3"):
        session.slave.doStep(0.0, step_s)
    assert any("communicationStepSize" in m for m in session.messages)
    session.slave.freeInstance()


@pytest.mark.parametrize("version", [3, 2])
def test_parameter_after_initialisation_is_rejected(fmus: dict[int, Path], version: int) -> None:
    session = Session(fmus[version], version)
    session.enter_init()
    session.slave.exitInitializationMode()
    with pytest.raises(FMICallException):
        session.set("gear_ratio", 20.0)
    assert any("gear_ratio" in m and "fixed" in m for m in session.messages)
    session.slave.freeInstance()


def test_wrapper_missing_fmu_names_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.fmu"
    with pytest.raises(FmuError, match=r"nope[.]fmu: FMU file not found"):
        BeltDrive(missing)


def test_wrapper_malformed_fmu_names_file(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.fmu"
    garbage.write_text("not a zip")
    with pytest.raises(FmuError, match=r"garbage[.]fmu: not a valid FMU"):
        BeltDrive(garbage)
    empty = tmp_path / "empty.fmu"
    with zipfile.ZipFile(empty, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription")
    with pytest.raises(FmuError, match=r"empty[.]fmu: not a valid FMU"):
        BeltDrive(empty)


@pytest.mark.parametrize("version", [3, 2])
def test_wrapper_mapping_to_missing_variable_names_it(fmus: dict[int, Path], version: int) -> None:
    mapping = VariableMapping(belt_speed="conveyor.v")
    with pytest.raises(
        FmuError, match=r"BeltDrive.*\.fmu: mapping field 'belt_speed' names variable 'conveyor\.v'"
    ):
        BeltDrive(fmus[version], mapping=mapping)
    with pytest.raises(FmuError, match="parameter 'pulley_radius'"):
        BeltDrive(fmus[version], parameters={"pulley_radius": 0.1})


@pytest.mark.parametrize("version", [3, 2])
def test_wrapper_reports_fmu_logged_messages(fmus: dict[int, Path], version: int) -> None:
    with pytest.raises(FmuError, match="drum_radius_m = -1 is invalid"):
        BeltDrive(fmus[version], parameters={"drum_radius_m": -1.0})
    with BeltDrive(fmus[version]) as drive:
        drive.step(0.01, 0.5, 0.0)
        with pytest.raises(FmuError, match="speed_setpoint_mps = nan is invalid"):
            drive.step(0.01, math.nan, 0.0)
        with pytest.raises(FmuError, match=r"step dt_s = 0\.0 is invalid"):
            drive.step(0.0, 0.5, 0.0)
        assert drive.step(0.01, 0.5, 0.0).belt_speed_mps > 0.0
