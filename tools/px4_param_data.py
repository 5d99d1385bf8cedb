"""Write the simulated vehicle's PX4 parameter data from a PX4 v1.16 SITL build and the
parameter values bench/parity_timing.py recorded from it.

- sim/data/px4_sitl_params.json: per airframe (quad, vtol, plane), the values a fresh PX4
  SITL vehicle reports for the families scripts commonly read or set (MPC_, NAV_, RTL_, COM_,
  MIS_, and LNDMC_ where PX4 has them).
- sim/data/px4_parameters.json: PX4's parameter metadata (type, default, range, unit,
  descriptions, enum values, bitmasks) for every parameter the sim has on any airframe, in
  PX4's own format, which the sim serves as component metadata (COMP_METADATA_TYPE_PARAMETER).

    .venv/bin/python tools/px4_param_data.py [--px4-build /root/px4sitl/build/px4_sitl_default]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sim.lib.params import ParamStore  # noqa: E402
from sim.models.airframes import AIRFRAME_NAMES, param_defaults  # noqa: E402

REFERENCE = ROOT / "bench" / "px4_reference" / "parity_timing.json"
VALUES_OUT = ROOT / "sim" / "data" / "px4_sitl_params.json"
METADATA_OUT = ROOT / "sim" / "data" / "px4_parameters.json"
FAMILIES = ("MPC_", "NAV_", "RTL_", "COM_", "MIS_", "LNDMC_")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--px4-build", type=Path,
                        default=Path("/root/px4sitl/build/px4_sitl_default"))
    args = parser.parse_args()
    recorded = json.loads(REFERENCE.read_text())["params"]
    values = {
        airframe: {n: v for n, v in sorted(recorded[airframe].items()) if n.startswith(FAMILIES)}
        for airframe in ("quad", "vtol", "plane")
    }
    VALUES_OUT.write_text(json.dumps(values, indent=0, sort_keys=True) + "\n")
    names: set[str] = set()
    for airframe in AIRFRAME_NAMES:
        names |= set(ParamStore.for_airframe(airframe, param_defaults(airframe)))
    px4 = json.loads((args.px4_build / "parameters.json").read_text())
    chosen = [p for p in px4["parameters"] if p["name"] in names]
    missing = sorted(names - {p["name"] for p in chosen})
    METADATA_OUT.write_text(json.dumps(
        {"parameters": sorted(chosen, key=lambda p: p["name"]), "version": px4["version"]},
        separators=(",", ":"), sort_keys=True) + "\n")
    print(f"{VALUES_OUT.relative_to(ROOT)}: "
          + ", ".join(f"{a} {len(v)}" for a, v in values.items()))
    print(f"{METADATA_OUT.relative_to(ROOT)}: {len(chosen)} parameters; "
          f"without PX4 metadata: {missing}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
