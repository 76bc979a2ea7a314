"""Power mismatch at the mechanical ports: the coupling-error figure of a run.

A port is a pair of connections between two components: a torque [N.m] from the driver to the
receiver, and an angular speed [rad/s] from the receiver back to the driver. A monolithic model
would see one power torque * speed at the port; a co-simulation shows each side a different
one (an input held or extrapolated over the step against the other side's real output). Each
side's energy is integrated over every step with the trapezoidal rule, using the input as that
FMU saw it at the step's start and end (the master's polynomial; the held value for an FMU
without input derivatives) and the FMU's own output at both ends:

    E_receiver = sum h/2 (tau_seen(t) w(t) + tau_seen(t+h) w(t+h))
    E_driver   = sum h/2 (tau(t) w_seen(t) + tau(t+h) w_seen(t+h))

mismatch = E_receiver - E_driver [J]; relative mismatch = |mismatch| / the energy that passed the
port (sum of h/2 (|P(t)| + |P(t+h)|) on the driver's side).
"""
from __future__ import annotations

from dataclasses import dataclass

TORQUE_UNIT, SPEED_UNIT = "N.m", "rad/s"


@dataclass
class Port:
    receiver: str
    driver: str
    torque: str          # "driver.var -> receiver.var"
    speed: str           # "receiver.var -> driver.var"
    tau_out: int         # index in the driver's connected outputs
    tau_in: int          # index in the receiver's inputs
    w_out: int           # index in the receiver's connected outputs
    w_in: int            # index in the driver's inputs
    energy_receiver: float = 0.0
    energy_driver: float = 0.0
    throughput: float = 0.0


def find_ports(system) -> list[Port]:
    """Pair each torque connection with an unused speed connection running the other way."""
    def input_index(link):
        return [l for l in system.links if l.target == link.target].index(link)

    speeds = [l for l in system.links if l.unit == SPEED_UNIT]
    ports = []
    for tau in (l for l in system.links if l.unit == TORQUE_UNIT):
        back = next((w for w in speeds if w.source == tau.target and w.target == tau.source),
                    None)
        if back is None:
            continue
        speeds.remove(back)
        ports.append(Port(
            tau.target, tau.source, f"{tau.source}.{tau.source_var} -> {tau.target}.{tau.target_var}",
            f"{back.source}.{back.source_var} -> {back.target}.{back.target_var}",
            system.out_names[tau.source].index(tau.source_var), input_index(tau),
            system.out_names[back.source].index(back.source_var), input_index(back)))
    return ports


class PortPower:
    """Integrates each side's port power over the accepted steps."""

    def __init__(self, system):
        self.ports = find_ports(system)

    def add(self, h: float, before: dict, after: dict, seen: dict) -> None:
        for p in self.ports:
            (tau0, tau1), (w0, w1) = _ends(seen, p.receiver, p.tau_in), _ends(seen, p.driver, p.w_in)
            p.energy_receiver += 0.5 * h * (tau0 * before[p.receiver][p.w_out]
                                            + tau1 * after[p.receiver][p.w_out])
            P0 = before[p.driver][p.tau_out] * w0
            P1 = after[p.driver][p.tau_out] * w1
            p.energy_driver += 0.5 * h * (P0 + P1)
            p.throughput += 0.5 * h * (abs(P0) + abs(P1))

    def report(self) -> dict:
        ports = []
        for p in self.ports:
            mismatch = p.energy_receiver - p.energy_driver
            ports.append({"receiver": p.receiver, "driver": p.driver, "torque": p.torque,
                          "speed": p.speed, "energy_receiver_J": p.energy_receiver,
                          "energy_driver_J": p.energy_driver, "energy_throughput_J": p.throughput,
                          "mismatch_J": mismatch,
                          "relative_mismatch": abs(mismatch) / p.throughput if p.throughput
                          else None})
        rel = [q["relative_mismatch"] for q in ports if q["relative_mismatch"] is not None]
        return {"definition": "port energy mismatch, see crankfmu.masters.power",
                "max_relative_mismatch": max(rel) if rel else None, "ports": ports}


def _ends(seen: dict, comp: str, index: int) -> tuple[float, float]:
    """An input's value at the step's start and end, from the Taylor rows the FMU saw (only the
    ports' inputs are evaluated: in the order of masters.history.evaluate, so the same floats)."""
    rows, h = seen[comp]
    start = end = rows[0][index]
    if len(rows) > 1:
        end += rows[1][index] * h
    if len(rows) > 2:
        end += rows[2][index] * (0.5 * h * h)
    term = 0.5 * h * h
    for k in range(3, len(rows)):  # a Taylor coupling's higher rows
        term *= h / k
        end += rows[k][index] * term
    return start, end
