"""`crankfmu analyze impact`: the rocker impact paper's table for given parameters."""
from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("analyze", help="analytic results of the papers")
    what = p.add_subparsers(dest="analysis", required=True)
    impact = what.add_parser("impact", help="MO-100 table: Pm, tau, Tm, Tm/Pm, max dP, max dT "
                                            "per k_n, both readings of S")
    for name, unit in (("J", "kg m^2"), ("m", "kg"), ("r", "m"), ("R_c", "m"), ("d", "m"),
                       ("E", "Pa"), ("rho", "kg/m^3"), ("nu", "1"), ("V0", "m/s")):
        impact.add_argument(f"--{name}", type=float, help=f"[{unit}] (default: MO-100)")
    impact.add_argument("--k-n", type=float, nargs="+", default=[40e6, 80e6, 160e6],
                        help="support constants k_n [N^(2/3)/m]")
    impact.add_argument("--S-factor", type=float, nargs="+", default=[1.1, 0.9],
                        help="strike distance S as a multiple of the centre of percussion J/(m r)")
    impact.set_defaults(func=run_impact)


def run_impact(args) -> int:
    from ..physics.rocker_analysis import RockerData, format_impact_table, impact_table

    changes = {k: getattr(args, k) for k in ("J", "m", "r", "R_c", "d", "E", "rho", "nu", "V0")
               if getattr(args, k) is not None}
    rows = impact_table(RockerData(**changes), args.S_factor, args.k_n)
    print(format_impact_table(rows))
    return 0
