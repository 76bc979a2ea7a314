"""Human-readable and JSON reports of a structural analysis (`crankfmu structure MECH.toml`)."""
from __future__ import annotations

from .analysis import StructureResult, analyse
from .description import load_mechanism


def _pcounts(p_by: dict, prefix="p") -> str:
    return ", ".join(f"{prefix}{j} = {c}" for j, c in sorted(p_by.items(), key=lambda x: int(x[0])))


def format_report(r: StructureResult) -> str:
    L = []
    L.append(f"Mechanism {r.name} ({r.source})")
    L.append(f"  moving links n = {r.n}, joints p = {r.p} ({_pcounts(r.p_by_freedom)}), "
             f"independent loops k = p - n = {r.k}, joint freedoms f = {r.f}")
    if r.loops:
        L.append("  loops: " + "; ".join(f"{i + 1}: {lp}" for i, lp in enumerate(r.loops)))
    L.append("Counting formulas")
    if r.planar:
        pl = r.planar
        L.append(f"  planar (normal {pl['normal']}; in-plane {_pcounts(pl['p_planar'])}): "
                 f"Chebyshev W = 3n - 2p1 - p2 = {r.W_chebyshev}")
    else:
        L.append("  not planar: Chebyshev's formula does not apply")
    L.append(f"  Malyshev W = 6n - 5p1 - 4p2 - 3p3 - 2p4 - p5 = {r.W_malyshev} "
             f"(the mobility if there were no redundant constraints)")
    L.append(f"  with W = {r.W_formulas} (main mobility): Malyshev q = W - 6n + 5p1 + 4p2 + 3p3 "
             f"+ 2p4 + p5 = {r.q_malyshev}, Ozol q = W + 6k - f = {r.q_ozol}")
    L.append(f"Constraint Jacobian (loop closure, screw theory): {r.jacobian_shape[0]} x "
             f"{r.jacobian_shape[1]}, rank {r.rank}")
    L.append(f"  dof_total = f - rank = {r.dof_total}: main mobility {r.mobility} "
             f"(outputs {', '.join(r.outputs)}), local mobilities "
             f"{r.local_mobilities['count']}")
    for d in r.local_mobilities["directions"]:
        L.append(f"    local: {d}")
    L.append(f"  redundant constraints q = 6k - rank = {r.redundant['count']}")
    for d in r.redundant["directions"]:
        L.append(f"    redundant: {d}")
    if r.planar:
        pl = r.planar
        L.append(f"  in the plane: rank {pl['rank']}, dof {pl['dof']}, planar redundant "
                 f"constraints {pl['q']} (Chebyshev with W = {r.mobility}: "
                 f"q = W - 3n + 2p1 + p2 = {pl['q_chebyshev']})")
    L.append("Verdict")
    L.extend("  " + s for s in verdict(r))
    for note in r.notes:
        L.append(f"  note: {note}")
    return "\n".join(L)


def verdict(r: StructureResult) -> list[str]:
    q, main, local, dof = r.redundant["count"], r.mobility, r.local_mobilities["count"], \
        r.dof_total
    out = []
    if q == r.q_malyshev and dof == main:
        out.append(f"the formulas and the rank count agree: W = {main}, q = {q}.")
    else:
        out.append(f"the counting formulas with W = {main} give q = {r.q_malyshev} (Malyshev) "
                   f"= {r.q_ozol} (Ozol); the rank count finds q = {q}.")
        if r.q_malyshev < 0:
            out.append(f"q = {r.q_malyshev} < 0 is impossible: the formulas need W to count the "
                       f"local mobilities too.")
        if local:
            out.append(f"q = {q} holds with W = {dof} ({main} main + {local} local): "
                       f"with W = dof_total the formulas give q = {r.q_formulas_total}.")
        if r.q_malyshev >= 0 and local:
            out.append(f"the geometry is special: {local} local mobility(ies) and as many extra "
                       f"redundant constraints that a counting formula with W = {main} cannot "
                       f"see.")
    if q == 0:
        out.append("no redundant constraints: the mechanism assembles without preload "
                   "(statically determinate).")
    else:
        out.append(f"{q} redundant constraint(s): manufacturing errors in these directions "
                   f"load the joints at assembly (statically indeterminate).")
    return out


def structure_report(path, as_json: bool = False) -> str:
    """Analyse the mechanism file at `path`; the text report, or JSON if `as_json`."""
    result = analyse(load_mechanism(path))
    return result.to_json() if as_json else format_report(result)
