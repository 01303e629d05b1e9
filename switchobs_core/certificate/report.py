"""Certificates of a whole gain table (:func:`certify_table`) and their text report
(:func:`format_report`): the paper's factors beside the sound certificates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..bounds.envelope import schedule_segments
from ..exceptions import InvalidArgument
from ..model.schedule import PeriodicSchedule, SequenceSchedule, check_cycle_horizon
from ..validation import as_finite
from .box import certify_box
from .cycle import CycleCertificate, certify_cycle
from .lyapunov import common_lyapunov
from .paper import EnvelopeRatio, envelope_ratio, paper_factors

__all__ = ["TableReport", "certify_table", "format_report"]


@dataclass
class TableReport:
    """Paper's and sound certificates for every design of a table (``switchobs certify``)."""

    designs: list = field(default_factory=list)
    sequence: dict | None = None
    robust: dict | None = None

    def to_dict(self) -> dict:
        return {"designs": self.designs, "sequence": self.sequence, "robust": self.robust}


def _cycle_entry(system, design, cert: CycleCertificate, ratio: EnvelopeRatio | None) -> dict:
    return {
        "cycle": design.cycle.label() if design.cycle is not None else "robust",
        "h": list(cert.h),
        "eta": list(design.eta),
        "kappa": list(design.kappa),
        "paper": {"f": list(cert.f), "claims_convergence": cert.paper_ok,
                  "status": "the paper's claim (proof has a gap; not verified)"},
        "sound": {"spectral_radius": cert.spectral_radius, "norm": cert.norm,
                  "converges": cert.sound_ok,
                  "status": "verified (exact cycle transition, floating point)"},
        "envelope_ratio": None if ratio is None else {
            "worst": list(ratio.ratio), "t": list(ratio.t), "horizon": ratio.horizon,
            "exceeded": [r > 1 for r in ratio.ratio]},
    }


def certify_table(system: Any, table: Any, *, sequence: Sequence[Any] | None = None,
                  ratio_cycles: int = 5, ratio_dt: float = 0.002, box: bool = True) -> TableReport:
    """Certify every design of ``table`` (and a cycle sequence, and the robust design).

    Per design: the paper's factors, the exact cycle map's spectral radius and norm,
    and the worst envelope ratio over ``ratio_cycles`` periodic cycles. With
    ``sequence`` (a list of Cycles, each looked up in the table): the paper's factors of
    each, a common quadratic Lyapunov function for their cycle maps (any order), and the
    envelope ratio over the repeated sequence. For ``table.robust``: the box certificate.
    """
    if not isinstance(ratio_cycles, (int, np.integer)) or ratio_cycles < 1:
        raise InvalidArgument(f"ratio_cycles must be an integer >= 1; got {ratio_cycles!r}")
    if as_finite(ratio_dt, "ratio_dt") <= 0:
        raise InvalidArgument(f"ratio_dt must be > 0; got {ratio_dt}")
    if not table.designs:
        # a Kalman table holds gains per sample phase, no cycle design: nothing here applies
        raise InvalidArgument(
            f"nothing to certify: this table holds {table.family} gains, no LMI cycle design; the "
            "certificates are of the paper's LMI gains (its guarantee is the exact bound: switchobs simulate)")
    rep = TableReport()
    for c in [d.cycle for d in table.designs] + list(sequence or ()):
        check_cycle_horizon(system.A, c, "the table's cycle")
    for d in table.designs:
        cert = certify_cycle(system, d)
        sched = PeriodicSchedule(d.cycle)
        t_end = ratio_cycles * d.cycle.tau
        ratio = envelope_ratio(system, schedule_segments(sched, [d], t_end), t_end, dt=ratio_dt)
        rep.designs.append(_cycle_entry(system, d, cert, ratio))
    if sequence:
        designs = [table.lookup(c) for c in sequence]
        certs = [certify_cycle(system, d, c.h) for d, c in zip(designs, sequence)]
        lyap = common_lyapunov([c.Phi for c in certs])
        sched = SequenceSchedule(list(sequence))
        t_end = ratio_cycles * sum(c.tau for c in sequence) / max(len(sequence), 1) * 2
        ratio = envelope_ratio(system, schedule_segments(sched, designs, t_end), t_end, dt=ratio_dt)
        rep.sequence = {
            "cycles": [c.label() for c in sequence],
            "paper": {"f": [list(c.f) for c in certs],
                      "claims_convergence": all(c.paper_ok for c in certs),
                      "status": "the paper's claim (not verified)"},
            "sound": {"cycle_spectral_radius": [c.spectral_radius for c in certs],
                      "cycle_norm": [c.norm for c in certs],
                      "common_lyapunov_rho": lyap.rho, "rho_lower": lyap.rho_lower,
                      "cond_P": lyap.cond, "min_eig": lyap.min_eig, "margin": lyap.margin,
                      "verified": lyap.verified, "converges_any_order": lyap.ok,
                      "status": "verified (the LMI solution proved in floating point, rounding "
                                "included, at a rate backed off from the SDP's edge)"},
            "envelope_ratio": {"worst": list(ratio.ratio), "t": list(ratio.t),
                               "horizon": ratio.horizon},
        }
    if box and getattr(table, "robust", None) is not None:
        d = table.robust
        bc = certify_box(system, d)
        hmin, hmax = bc.h_min, bc.h_max
        worst_h = [hmin if i == 0 else hmax for i in range(len(system.C))]
        f_worst = [paper_factors(d, [hmin if j == i else hmax for j in range(len(system.C))])[i]
                   for i in range(len(system.C))]
        rep.robust = {
            "h_bounds": [hmin, hmax],
            "eta": list(d.eta),
            "paper": {"f_worst": f_worst, "claims_convergence": max(f_worst) < 1,
                      "status": "the paper's claim at the worst corner (not verified)"},
            "sound": {"rho": bc.rho, "c": list(bc.c), "grid_rho": bc.grid_rho,
                      "cells": bc.cells, "cond_P1": bc.cond, "converges_all_schedules": bc.ok,
                      "status": "verified over the whole box (grid + rigorous remainder)"},
            "worst_h_example": worst_h,
        }
    return rep


def format_report(rep: TableReport) -> str:
    """Plain-text side-by-side rendering of a :class:`TableReport`."""
    lines = []
    hdr = (f"{'cycle':<16} {'eta':<16} {'paper f_ii (claim)':<24} {'paper says':<11} "
           f"{'rho(Phi)':>9} {'||Phi||':>9} {'verified':<9} {'env. ratio (worst)':<20}")
    lines.append("Per design: the paper's certificate (claim, proof has a gap) | sound certificate (verified)")
    lines.append(hdr)
    lines.append("-" * len(hdr))
    for e in rep.designs:
        f = ", ".join(f"{x:.4f}" for x in e["paper"]["f"])
        eta = ", ".join(f"{x:.3g}" for x in e["eta"])
        r = e["envelope_ratio"]
        rs = ", ".join(f"{x:.2f}" for x in r["worst"]) if r else "-"
        lines.append(f"{e['cycle']:<16} {eta:<16} {f:<24} "
                     f"{'converges' if e['paper']['claims_convergence'] else 'no claim':<11} "
                     f"{e['sound']['spectral_radius']:>9.4f} {e['sound']['norm']:>9.3f} "
                     f"{'yes' if e['sound']['converges'] else 'NO':<9} {rs:<20}")
    lines.append("env. ratio = max over initial errors and t of ||x_o^(i)(t)|| / z_i(t) "
                 "(> 1: the paper's envelope z_i is exceeded)")
    if rep.sequence:
        s = rep.sequence
        lines.append("")
        lines.append("Sequence " + " ".join(s["cycles"]) + " (any order of these cycle types):")
        lines.append("  paper (claim):  f_ii per cycle = " + "; ".join(
            ", ".join(f"{x:.4f}" for x in f) for f in s["paper"]["f"]))
        so = s["sound"]
        lines.append(f"  sound (verified): common Lyapunov rho = {so['common_lyapunov_rho']:.4f} per cycle "
                     f"(lower bound {so['rho_lower']:.4f}), cond(P) = {so['cond_P']:.3g}, "
                     f"verified = {so['verified']}, converges for any order = {so['converges_any_order']}")
        lines.append("  envelope ratio (worst) = " + ", ".join(f"{x:.2f}" for x in s["envelope_ratio"]["worst"]))
    if rep.robust:
        r = rep.robust
        lines.append("")
        lines.append(f"Robust design, residence times in [{r['h_bounds'][0]:g}, {r['h_bounds'][1]:g}] s:")
        lines.append("  paper (claim, worst corner): f_ii = " + ", ".join(f"{x:.4f}" for x in r["paper"]["f_worst"]))
        so = r["sound"]
        lines.append(f"  sound (verified over the whole box): rho = {so['rho']:.4f} per cycle "
                     f"(grid only {so['grid_rho']:.4f}, {so['cells']} cells/channel), "
                     f"converges for all schedules = {so['converges_all_schedules']}")
    return "\n".join(lines)
