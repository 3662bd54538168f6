#!/usr/bin/env python3
"""Fails when an effect's code is spread over a crate: each effect's names (its type, its SPEC
name, its constants) may appear in code only in its own module, in the crate's registry of
effects and re-exports, and in the withheld-effect benchmark's plant (a second, independent
form of every effect). Comments and strings are not code.

    python3 .ci/effect_homes.py CRATE [CRATE ...]

Only the crates given are checked (motor-model: every effect in `src/sim/effects/<effect>.rs`).
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from import_cycles import strip_comments_and_strings, without_test_modules  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent / "crates"

# effect -> identifiers that are its own
EFFECTS = {
    "stribeck_friction": ["StribeckFriction", "stribeck_friction", "STRIBECK"],
    "cogging_torque": ["CoggingTorque", "cogging_torque", "COGGING"],
    "current_sensor_lag": ["CurrentSensorLag", "current_sensor_lag", "SENSOR_LAG"],
    "thermal_drift": ["ThermalDrift", "thermal_drift", "THERMAL"],
    "quadratic_drag": ["QuadraticDrag", "quadratic_drag", "DRAG_PARAMS"],
    "brush_drop": ["BrushDrop", "brush_drop", "BRUSH"],
    "inductance_saturation": ["InductanceSaturation", "inductance_saturation", "SATURATION_PARAMS"],
}

# crate -> (the effect's own module for effect e, files allowed for every effect)
HOMES = {
    "motor-model": (
        lambda e: {
            "stribeck_friction": "src/sim/effects/stribeck.rs",
            "cogging_torque": "src/sim/effects/cogging.rs",
            "current_sensor_lag": "src/sim/effects/sensor_lag.rs",
            "thermal_drift": "src/sim/effects/thermal.rs",
            "quadratic_drag": "src/sim/effects/drag.rs",
            "brush_drop": "src/sim/effects/brush.rs",
            "inductance_saturation": "src/sim/effects/saturation.rs",
        }[e],
        # the registry, the crate's table of contents, the benchmark's plant
        ("src/sim/effects/mod.rs", "src/lib.rs", "src/withheld/"),
    ),
}


def main() -> int:
    crates = sys.argv[1:] or sorted(HOMES)
    failed = False
    for crate in crates:
        if crate not in HOMES:
            print(f"{crate}: no effect modules declared (known: {', '.join(sorted(HOMES))})")
            return 2
        own_of, shared = HOMES[crate]
        src = ROOT / crate / "src"
        for path in sorted(src.rglob("*.rs")):
            rel = path.relative_to(ROOT / crate).as_posix()
            if any(rel == s or (s.endswith("/") and rel.startswith(s)) for s in shared):
                continue
            code = without_test_modules(strip_comments_and_strings(path.read_text()))
            for effect, names in EFFECTS.items():
                if rel == own_of(effect):
                    continue
                for name in names:
                    for m in re.finditer(r"\b\w*" + re.escape(name) + r"\w*\b", code):
                        line = code.count("\n", 0, m.start()) + 1
                        print(f"{crate}/{rel}:{line}: `{m.group(0)}` belongs to {effect}'s module "
                              f"({own_of(effect)}) or the registry")
                        failed = True
    if failed:
        print("an effect's code is spread over modules: move it to the effect's own module")
        return 1
    print(f"every effect's code in its own module ({', '.join(crates)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
