"""A third party's belt drive, written for pythonfmu: the belt speed lags its setpoint.

This file is the model script that ``pythonfmu build`` packs into an FMI 2.0 co-simulation FMU
(:func:`tests.fmus.pythonfmu_belt.build_belt_fmu`); the FMU runs it in the host's Python
through pythonfmu's export library. It stands for a drive from another tool: its variables have
other names than our BeltDrive's, and it has no motor torque or current.

Model (SI units): ``dv/dt = (v_set - v) / T``, ``dx/dt = v`` with the lag
``T = T_lag * (1 + m_load / m_belt)`` (a heavier load makes the belt slower to follow). With the
inputs held over a step of length ``h`` and ``d = exp(-h / T)``, each step is integrated
exactly::

    v(t + h) = v_set + (v(t) - v_set) * d
    x(t + h) = x(t) + v_set * h + (v(t) - v_set) * T * (1 - d)

Variables: inputs ``v_set`` (m/s) and ``m_load`` (kg), outputs ``v_belt`` (m/s) and ``x_belt``
(m), parameters ``T_lag`` (s) and ``m_belt`` (kg).
"""

from __future__ import annotations

import math
from typing import Any

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real


class LagBelt(Fmi2Slave):
    """A conveyor whose speed follows its setpoint as a first-order lag (see the module)."""

    author = "cdw-twin tests"
    description = "Belt speed as a first-order lag of its setpoint, slower under load"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.v_set = 0.0
        self.m_load = 0.0
        self.v_belt = 0.0
        self.x_belt = 0.0
        self.T_lag = 0.25
        self.m_belt = 50.0
        for name in ("v_set", "m_load"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("v_belt", "x_belt"):  # the belt starts at rest, at 0
            self.register_variable(
                Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact)
            )
        for name in ("T_lag", "m_belt"):
            self.register_variable(
                Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)
            )

    def do_step(self, current_time: float, step_size: float) -> bool:
        """Advance the belt over ``step_size`` seconds with the inputs held (exact solution)."""
        del current_time
        lag_s = self.T_lag * (1.0 + self.m_load / self.m_belt)
        if not (math.isfinite(lag_s) and lag_s > 0.0):
            return False
        decay = math.exp(-step_size / lag_s)
        offset = self.v_belt - self.v_set
        self.x_belt += self.v_set * step_size + offset * lag_s * (1.0 - decay)
        self.v_belt = self.v_set + offset * decay
        return True
