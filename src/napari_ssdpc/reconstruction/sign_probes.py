"""The sign of a sample when it is not known: ``tv`` probes both signs (denser, lighter than the
medium) with a short solve each and goes on with the one whose objective is lower."""

from __future__ import annotations

__all__ = ["PROBE", "solve_with_auto_sign"]

#: Iterations of each sign's probe solve when the sign is 'auto'.
PROBE = 12


def solve_with_auto_sign(inversion, contrast, warm, phi_max, lam, iterations, tol, progress, should_stop):
    """``tv`` with the sign the data support: a short solve with each, the lower objective wins,
    then the rest of the iterations with it. Progress counts against ``iterations`` (the chosen
    sign's path: its probe, then the rest), each probe labelled; both probes stop with
    ``should_stop``.

    Parameters
    ----------
    inversion : TvInversion
        Its ``phase`` solves with a given sign.
    contrast, warm, phi_max, lam, iterations, tol, progress, should_stop
        As for ``TvInversion.phase``.

    Returns
    -------
    phi : ndarray
        The phase, rad.
    report : TvReport
        The chosen sign's path, with ``sign_objectives`` and ``sign`` ('auto: ...').
    """

    total = max(iterations, PROBE + 1)

    def report_as(label, offset=0):
        return None if progress is None else (lambda i, n, *_: progress(offset + i, total, label))

    kw = dict(warm=warm, phi_max=phi_max, lam=lam, iterations=PROBE, tol=0.0, quiet=True, should_stop=should_stop)
    probes = {
        s: inversion.phase(contrast, sign=s, progress=report_as(f"TV: probing the sign ({s})"), **kw)
        for s in ("denser", "lighter")
    }
    if should_stop is not None and should_stop():  # cancelled while probing: the estimate so far
        return probes["denser"]
    best = min(probes, key=lambda s: probes[s][1].objective[-1])
    other = "lighter" if best == "denser" else "denser"
    phi, report = inversion.phase(
        contrast,
        warm=probes[best][0],
        sign=best,
        phi_max=phi_max,
        lam=lam,
        iterations=max(iterations - PROBE, 1),
        tol=tol,
        progress=report_as(f"TV ({best})", PROBE),
        should_stop=should_stop,
    )
    report.sign_objectives = {s: probes[s][1].objective[-1] for s in probes}
    report.objective = probes[best][1].objective + report.objective
    report.relative_change = probes[best][1].relative_change + report.relative_change
    report.iterations += PROBE  # the chosen sign's path; the other probe ran PROBE more
    report.sign = f"auto: {best} (objective {report.sign_objectives[best]:.4g} vs {other} "
    report.sign += f"{report.sign_objectives[other]:.4g})"
    return phi, report
