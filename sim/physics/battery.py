"""A battery that drains with the electric power the airframe draws.

Like PX4's SITL battery simulator it never drops below SIM_BAT_MIN_PCT, so long
simulations do not end in a low-battery failsafe.
"""

from __future__ import annotations

from sim.lib.params import ParamReader

# Current at full power; a 1 kg quad hovering draws about a quarter of it.
MAX_CURRENT_A = 60.0
IDLE_CURRENT_A = 0.4
# BAT1_CAPACITY -1 (PX4 SITL's value) means "unknown": drain as a pack of this size
NOMINAL_CAPACITY_MAH = 5000.0


class Battery:
    def __init__(self, params: ParamReader) -> None:
        self._params = params
        self.remaining = 1.0
        self.current_a = IDLE_CURRENT_A
        self.consumed_mah = 0.0

    def update(self, dt_s: float, power_fraction: float) -> None:
        self.current_a = IDLE_CURRENT_A + MAX_CURRENT_A * min(max(power_fraction, 0.0), 1.0)
        used_mah = self.current_a * dt_s / 3.6
        self.consumed_mah += used_mah
        capacity_mah = self._params.get("BAT1_CAPACITY")
        if capacity_mah <= 0.0:
            capacity_mah = NOMINAL_CAPACITY_MAH
        capacity_mah = max(capacity_mah, 1.0)
        floor = min(max(self._params.get("SIM_BAT_MIN_PCT") / 100.0, 0.0), 1.0)
        self.remaining = max(floor, self.remaining - used_mah / capacity_mah)

    @property
    def cell_count(self) -> int:
        return max(int(self._params.get("BAT1_N_CELLS")), 1)

    @property
    def cell_voltage_v(self) -> float:
        empty = self._params.get("BAT1_V_EMPTY")
        charged = self._params.get("BAT1_V_CHARGED")
        sag = 0.002 * self.current_a
        return empty + (charged - empty) * self.remaining - sag

    @property
    def voltage_v(self) -> float:
        return self.cell_voltage_v * self.cell_count

    @property
    def remaining_percent(self) -> int:
        return round(self.remaining * 100.0)
