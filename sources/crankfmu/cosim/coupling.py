"""Which couplings a scene's FMUs allow: a Taylor coupling ([master].taylor = q,
masters/taylor.py) needs every FMU whose outputs are connected to offer their derivatives 1 .. q
(the companion outputs <output>_d1 ...). The accuracy study's default grid and the --target
search ask this before they try one."""
from __future__ import annotations

from pathlib import Path


def taylor_orders_offered(scene, fmu_dir=None, wanted=(1, 2, 3, 4)) -> list[int]:
    """The orders q in `wanted` for which every connected output of the scene has the
    companions <output>_d1 .. _dq in its FMU's modelDescription (catalog FMUs are built when
    missing or stale, as a run would)."""
    from fmpy import read_model_description

    from ..system.wiring import default_fmu_dir, resolve_fmu

    fmu_dir = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir(scene)
    sources: dict[str, set[str]] = {}
    for c in scene.connections:
        comp, var = c.source.split(".", 1)
        sources.setdefault(comp, set()).add(var)
    if not sources:
        return []
    outputs: dict[str, set[str]] = {}
    for comp in sources:
        md = read_model_description(str(resolve_fmu(scene, comp, fmu_dir)), validate=False)
        outputs[comp] = {v.name for v in md.modelVariables if v.causality == "output"}
    return [q for q in wanted
            if all(f"{var}_d{k}" in outputs[comp] for comp, names in sources.items()
                   for var in names for k in range(1, q + 1))]
