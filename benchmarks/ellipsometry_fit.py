"""E1: a 3-angle × 700-wavelength ψ/Δ fit of a Cauchy film on native SiO2 on Si — layerstack vs pyElli.

    python -m benchmarks.ellipsometry_fit [--processes 3] [--repeats 10] [--wavelengths 700]

The problem (issue 15's performance target): air / Cauchy film (d = 120 nm, A = 1.55,
B = 0.0080 µm²) / native SiO2 (2.0 nm, Malitson) / Si (Aspnes), ψ and Δ at 55°, 65° and 75°
on ``--wavelengths`` points evenly spaced in 300–820 nm (inside both tables). Free: the film's
thickness (bounds 20–300 nm) and Cauchy A, B (start 100 nm, 1.50, 0.0050 µm²; A ≥ 1, the
library's default bound of an index, B unbounded, as in the first runs — with B bounded to
[0, 0.05] and A to [1.2, 2.2] the fit takes 55 steps on 40 wavelengths, ``benchmarks/README.md``).
The data are made by **pyElli**
(``elli.Structure.evaluate``, 2×2 solver; the SiO2 and Si constants handed to it as tables on
the same wavelengths, exact at the nodes) — not by the code under test — plus Gaussian noise
σψ = σΔ = 0.02°; every repeat draws new noise.

Timed, in each fresh process (``--processes`` of them; the figures are the best process):

* **layerstack** (``fitting.Objective`` with six ``Ellipsometric`` datasets, σ given;
  ``fitting.fit``, Levenberg–Marquardt with the library's stopping rules, :data:`FIT_OPTIONS`):
  building the objective; the first ``fit`` (trace, compile, solve, statistics, report
  ingredients); each further fit of the same objective on new
  data (``fit(objective, data=...)``: the compiled solver is reused) — min and median over
  ``--repeats``; compile ≈ first fit − median further fit; ``fit(objective, starts=16)`` — 16
  starts solved one after the other by the fit's compiled solver (hopeless starts given up:
  ``fitting._multistart.give_up_rule``), a first and a second call. The XLA compilations of each
  step are counted from JAX's compile events (``jax.monitoring``).
* **pyElli**: the same weighted least squares (ψ, Δ residuals / σ, Δ wrapped) over pyElli's
  forward model, minimised by ``scipy.optimize.least_squares(method="lm")`` — MINPACK's
  Levenberg–Marquardt with a finite-difference Jacobian, the algorithm behind
  ``lmfit.minimize``'s default ``"leastsq"`` that pyElli's own fitting classes call (lmfit itself
  is not a dependency here; pyElli's ``elli.fitting`` needs lmfit, plotly and ipywidgets and fits
  one angle at a time in a notebook widget). Same start, same data; min and median per fit.

Checks (a benchmark must not time a wrong model): layerstack's ψ, Δ at the truth equal pyElli's
to ≤ 1e-9°; the two codes' fitted values agree to ≤ 1e-3 of layerstack's standard errors on
every repeat; the truth lies within 5 standard errors. Writes
``benchmarks/results/ellipsometry_fit.md`` and ``.json`` (with ``--out-dir``, elsewhere).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ANGLES = (55.0, 65.0, 75.0)
TRUTH = {"d": 120.0, "A": 1.55, "B": 0.0080}  # nm, -, µm²
START = {"d": 100.0, "A": 1.50, "B": 0.0050}
BOUNDS = {"d": (20.0, 300.0), "A": (None, None), "B": (None, None)}  # A, B: no bounds (module docstring)
OXIDE_NM = 2.0
SIGMA_DEG = 0.02
#: stopping rules of layerstack's fits: the library's defaults (a solve ends within 1e-3 standard errors
#: of its minimum, ``sigma_tol``). Before that rule, the defaults' step test (rtol 1e-10) ran 5 of 6
#: fits of this problem to max_steps = 256 at the optimum and this benchmark used rtol 1e-8.
FIT_OPTIONS: dict = {}
#: layerstack vs pyElli, in standard errors: each solve stops within 1e-3 of its own minimum
AGREEMENT_STDERR = 2e-3
TARGETS = {"compile_s": 3.0, "further_fit_s": 0.050, "multistart16_s": 5.0}
#: the timings of a process; the report gives each one's best over the processes
TIMED = ("objective_s", "first_fit_s", "compile_s", "further_fit_min_s", "further_fit_median_s", "multistart_first_s",
         "multistart_s", "pyelli_fit_min_s", "pyelli_fit_median_s", "first_fit_cpu_s", "compile_cpu_s",
         "further_fit_median_cpu_s", "multistart_first_cpu_s", "multistart_cpu_s", "pyelli_fit_median_cpu_s")


def wavelengths(n: int) -> np.ndarray:
    return np.linspace(300.0, 820.0, n)


# ------------------------------------------------------------------------------- pyElli side
def pyelli_model(wl: np.ndarray):
    """``psi_delta(d, A, B) -> (psi, delta)`` each ``(angle, wl)`` in degrees, by pyElli's 2×2
    solver; SiO2 and Si from the library's tables on ``wl`` (pyElli's ``Table`` interpolates
    linearly, exact at its nodes), the film as pyElli's own Cauchy (n0 + 100 n1/λ², λ in nm:
    n1 = 1e4 B for B in µm²)."""
    import elli

    import layerstack_jax as ls

    si = elli.IsotropicMaterial(elli.Table(lbda=wl, n=np.asarray(ls.material("Si", "Aspnes")(wl))))
    sio2 = elli.IsotropicMaterial(elli.Table(lbda=wl, n=np.asarray(ls.material("SiO2", "Malitson")(wl))))

    def psi_delta(d, A, B):
        film = elli.Cauchy(n0=float(A), n1=1e4 * float(B)).get_mat()
        st = elli.Structure(elli.AIR, [elli.Layer(film, float(d)), elli.Layer(sio2, OXIDE_NM)], si)
        res = [st.evaluate(wl, a, solver=elli.Solver2x2) for a in ANGLES]
        return np.array([np.asarray(r.psi) for r in res]), np.array([np.asarray(r.delta) for r in res])

    return psi_delta


def pyelli_fit(psi_delta, psi_m, delta_m, x0):
    """scipy MINPACK Levenberg–Marquardt (lmfit's default) over pyElli: ``(x, nfev)``."""
    from scipy.optimize import least_squares

    def residuals(x):
        psi, delta = psi_delta(*x)
        return np.concatenate([((psi - psi_m) / SIGMA_DEG).ravel(),
                               (((delta - delta_m + 180.0) % 360.0 - 180.0) / SIGMA_DEG).ravel()])

    r = least_squares(residuals, x0, method="lm", x_scale=np.abs(np.asarray(x0)), xtol=1e-10, ftol=1e-10)
    return r.x, int(r.nfev)


# --------------------------------------------------------------------------- layerstack side
def objective(wl, psi_m, delta_m):
    """The fitting objective: six datasets (ψ, Δ at each angle) with σ, three free parameters."""
    import fitting
    import layerstack_jax as ls

    film = ls.Layer(ls.Cauchy(START["A"], START["B"]), START["d"], name="film")
    oxide = ls.Layer(ls.material("SiO2", "Malitson"), OXIDE_NM, name="oxide")
    stack = ls.Stack(1.0, [film, oxide], ls.Substrate(ls.material("Si", "Aspnes")))
    datasets = []
    for i, a in enumerate(ANGLES):
        datasets.append(fitting.Dataset(ls.Ellipsometric(a, "psi"), psi_m[i], sigma=SIGMA_DEG))
        datasets.append(fitting.Dataset(ls.Ellipsometric(a, "delta"), delta_m[i], sigma=SIGMA_DEG))
    params = [fitting.thickness("film", lower=BOUNDS["d"][0], upper=BOUNDS["d"][1]),
              fitting.dispersion("film", "A", lower=BOUNDS["A"][0], upper=BOUNDS["A"][1]),
              fitting.dispersion("film", "B", lower=BOUNDS["B"][0], upper=BOUNDS["B"][1])]
    return fitting.Objective(stack, wl, datasets, params)


#: JAX's compile events seen while :func:`_timed` runs: count and seconds per event name
_EVENTS: dict = {}
_WATCH = {"on": False}


def _listen(event, duration, **kwargs):
    if _WATCH["on"] and event.startswith("/jax/core/compile/"):
        n, t = _EVENTS.get(event, (0, 0.0))
        _EVENTS[event] = (n + 1, t + duration)


def _timed(f, *args, **kwargs):
    """``(f(...), wall seconds, CPU seconds of this process — all its threads)``; the compile
    events of the call are left in :data:`_EVENTS`."""
    _EVENTS.clear()
    _WATCH["on"] = True
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        out = f(*args, **kwargs)
        return out, time.perf_counter() - t0, time.process_time() - c0
    finally:
        _WATCH["on"] = False


def _compiles() -> dict:
    """XLA compilations of the last :func:`_timed` call, and seconds (wall) spent tracing,
    lowering and compiling (JAX's own compile events)."""
    n, compile_s = _EVENTS.get("/jax/core/compile/backend_compile_duration", (0, 0.0))
    return {"n": n, "compile_s": compile_s,
            "trace_s": _EVENTS.get("/jax/core/compile/jaxpr_trace_duration", (0, 0.0))[1],
            "lower_s": _EVENTS.get("/jax/core/compile/jaxpr_to_mlir_module_duration", (0, 0.0))[1]}


def _values(result) -> np.ndarray:
    """(d nm, A, B µm²): the flat parameter vector, in the order the objective declares them."""
    return np.asarray(result.x, float)


def _as_data(psi, delta):
    """One ``(1, wl)`` array per dataset in the objective's order (ψ, Δ per angle)."""
    return [a[None] for i in range(len(ANGLES)) for a in (psi[i], delta[i])]


def run(n_wavelengths: int = 700, repeats: int = 10, starts: int = 16, seed: int = 0) -> dict:
    """One process's measurements (module docstring); returns a JSON-able dict."""
    import jax

    jax.config.update("jax_enable_x64", True)
    if os.environ.get("E1_COMPILATION_CACHE"):  # the warm-cache processes (main)
        jax.config.update("jax_compilation_cache_dir", os.environ["E1_COMPILATION_CACHE"])
    if not _WATCH.get("registered"):  # once per process
        jax.monitoring.register_event_duration_secs_listener(_listen)
        _WATCH["registered"] = True
    import fitting
    import layerstack_jax as ls

    wl = wavelengths(n_wavelengths)
    rng = np.random.default_rng(seed)
    psi_delta = pyelli_model(wl)
    psi_t, delta_t = psi_delta(TRUTH["d"], TRUTH["A"], TRUTH["B"])

    # the model check: layerstack at the truth equals pyElli (Δ modulo 360°)
    truth_stack = ls.Stack(1.0, [ls.Layer(ls.Cauchy(TRUTH["A"], TRUTH["B"]), TRUTH["d"]),
                                 ls.Layer(ls.material("SiO2", "Malitson"), OXIDE_NM)],
                           ls.Substrate(ls.material("Si", "Aspnes")))
    e = ls.ellipsometry(truth_stack, wl, np.asarray(ANGLES))
    model_check = max(float(np.max(np.abs(np.asarray(e.psi_deg) - psi_t))),
                      float(np.max(np.abs((np.asarray(e.delta_deg) - delta_t + 180.0) % 360.0 - 180.0))))

    def noisy():
        return (psi_t + SIGMA_DEG * rng.standard_normal(psi_t.shape),
                delta_t + SIGMA_DEG * rng.standard_normal(delta_t.shape))

    sets = [noisy() for _ in range(repeats + 1)]
    obj, t_objective, _ = _timed(objective, wl, *sets[0])
    first, t_first, c_first = _timed(fitting.fit, obj, **FIT_OPTIONS)
    compiles = {"first_fit": _compiles(), "further_fits": 0}
    ours, further, further_cpu = [_values(first)], [], []
    stderr = [np.asarray(first.x_stderr, float)]
    converged = [bool(first.converged)]
    for psi_m, delta_m in sets[1:]:
        r, t, c = _timed(fitting.fit, obj, data=_as_data(psi_m, delta_m), **FIT_OPTIONS)
        compiles["further_fits"] += _compiles()["n"]
        further.append(t)
        further_cpu.append(c)
        ours.append(_values(r))
        stderr.append(np.asarray(r.x_stderr, float))
        converged.append(bool(r.converged))

    multi, t_multi_first, c_multi_first = _timed(fitting.fit, obj, starts=starts, progress=False, **FIT_OPTIONS)
    compiles["multistart_first"] = _compiles()["n"]
    multi2, t_multi, c_multi = _timed(fitting.fit, obj, starts=starts, progress=False, data=_as_data(*sets[1]),
                                      **FIT_OPTIONS)
    compiles["multistart"] = _compiles()["n"]

    x0 = [START["d"], START["A"], START["B"]]
    theirs, t_elli, nfev = [], [], []
    elli_cpu = []
    for psi_m, delta_m in sets:
        (x, n), t, c = _timed(pyelli_fit, psi_delta, psi_m, delta_m, x0)
        t_elli.append(t)
        elli_cpu.append(c)
        theirs.append(x)
        nfev.append(n)

    ours, theirs, stderr = np.array(ours), np.array(theirs), np.array(stderr)
    truth = np.array([TRUTH["d"], TRUTH["A"], TRUTH["B"]])
    median_further = float(np.median(further)) if further else float("nan")
    return {
        "n_wavelengths": int(n_wavelengths), "angles_deg": list(ANGLES), "repeats": int(repeats),
        "starts": int(starts), "points": int(2 * len(ANGLES) * n_wavelengths),
        "model_check_deg": model_check,
        "objective_s": t_objective,
        "first_fit_s": t_first,
        "compile_s": t_first - median_further,
        "first_fit_cpu_s": c_first,
        "compile_cpu_s": c_first - (float(np.median(further_cpu)) if further_cpu else float("nan")),
        "further_fit_median_cpu_s": float(np.median(further_cpu)) if further_cpu else float("nan"),
        "multistart_first_cpu_s": c_multi_first,
        "multistart_cpu_s": c_multi,
        "further_fit_min_s": float(np.min(further)) if further else float("nan"),
        "further_fit_median_s": median_further,
        "steps_first": int(first.num_steps),
        "multistart_first_s": t_multi_first,
        "multistart_s": t_multi,
        "multistart_converged": [multi.starts_converged, multi2.starts_converged],
        "multistart_abandoned": [multi.starts_abandoned, multi2.starts_abandoned],
        "multistart_steps": [int(multi.num_steps), int(multi2.num_steps)],
        "compiles": compiles,
        "multistart_values": _values(multi).tolist(),
        "pyelli_fit_min_s": float(np.min(t_elli)),
        "pyelli_fit_median_s": float(np.median(t_elli)),
        "pyelli_fit_median_cpu_s": float(np.median(elli_cpu)),
        "pyelli_nfev_median": float(np.median(nfev)),
        "all_converged": all(converged),
        "values_layerstack": ours.tolist(),
        "values_pyelli": theirs.tolist(),
        "stderr_layerstack": stderr.tolist(),
        "max_disagreement_in_stderr": float(np.max(np.abs(ours - theirs) / stderr)),
        "max_error_in_stderr": float(np.max(np.abs(ours - truth) / stderr)),
        "multistart_vs_single_in_stderr": float(np.max(np.abs(_values(multi) - ours[0]) / stderr[0])),
        "loadavg": list(os.getloadavg()),
    }


def markdown(best: dict, runs: list, machine: dict, uptime: str) -> list[str]:
    t = TARGETS
    ok = lambda v, lim: "yes" if v <= lim else "**NO**"  # noqa: E731

    def each(key, factor=1.0, digits=2):
        return ", ".join(f"{factor * r[key]:.{digits}f}" for r in runs)

    d_ours = np.array(best["values_layerstack"][0])
    d_elli = np.array(best["values_pyelli"][0])
    se = np.array(best["stderr_layerstack"][0])
    lines = [
        f"# E1: ψ/Δ fit, 3 angles × {best['n_wavelengths']} λ, Cauchy film on native SiO2 on Si — layerstack vs pyElli",
        "",
        f"Run {machine['timestamp']} (git {machine.get('git')}), {machine.get('cpu_model')}, "
        f"{machine.get('cpu_count')} CPUs, {machine.get('mem_total_gib')} GiB, jax {machine['versions'].get('jax')} "
        f"(CPU backend, float64), pyElli {machine.get('pyelli')}, scipy {machine['versions'].get('scipy')}. "
        f"`uptime` at the start: `{uptime}`. Best of {len(runs)} fresh processes "
        f"(each timing: its best over the processes; each process: {best['repeats']} further fits, "
        f"{best['starts']} starts); 1-minute load average in the processes: "
        + ", ".join(f"{r['loadavg'][0]:.1f}" for r in runs) + ".",
        "",
        "Wall time is what a user waits; on this shared machine it is inflated by the other processes "
        "(the load above), so the CPU time of the benchmark process (all its threads, `time.process_time`) "
        "is given too: on an idle machine the wall time of the compile-bound rows is close to it.",
        "",
        "| quantity | measured, wall (best of the processes) | CPU time of the process (best) | each process, wall | target | met? (wall) |",
        "| --- | --- | --- | --- | --- | --- |",
        f"| build the `Objective` (trace once) | {best['objective_s']:.2f} s | | {each('objective_s')} s | — | — |",
        f"| first `fit` (trace + compile + solve, {best['steps_first']} LM steps) | {best['first_fit_s']:.2f} s | "
        f"{best['first_fit_cpu_s']:.2f} s | {each('first_fit_s')} s | — | — |",
        f"| compile (first fit − median further fit) | {best['compile_s']:.2f} s | {best['compile_cpu_s']:.2f} s | "
        f"{each('compile_s')} s | ≤ {t['compile_s']:g} s | {ok(best['compile_s'], t['compile_s'])} |",
        *([f"| first `fit` in a fresh process, JAX's persistent compilation cache warm (as `layerstack fit` from "
           f"its second run on; the process that filled it: {best['warm_cache']['filling_first_fit_s']:.2f} s) | "
           f"{best['warm_cache']['first_fit_s']:.2f} s | {best['warm_cache']['first_fit_cpu_s']:.2f} s | | — | — |"]
          if "warm_cache" in best else []),
        f"| further fit, same objective, new data (min / median) | {1e3 * best['further_fit_min_s']:.1f} / "
        f"{1e3 * best['further_fit_median_s']:.1f} ms | {1e3 * best['further_fit_median_cpu_s']:.1f} ms (median) | "
        f"{each('further_fit_median_s', 1e3, 0)} ms (medians) | ≤ {1e3 * t['further_fit_s']:g} ms | "
        f"{ok(best['further_fit_median_s'], t['further_fit_s'])} |",
        f"| {best['starts']}-start multi-start, the fit's compiled solver start after start (second call) | "
        f"{best['multistart_s']:.2f} s | "
        f"{best['multistart_cpu_s']:.2f} s | {each('multistart_s')} s | ≤ {t['multistart16_s']:g} s | "
        f"{ok(best['multistart_s'], t['multistart16_s'])} |",
        f"| the same, first call (compiles nothing: the single fit's solver) | {best['multistart_first_s']:.2f} s | "
        f"{best['multistart_first_cpu_s']:.2f} s | {each('multistart_first_s')} s | (≤ {t['multistart16_s']:g} s) | "
        f"{ok(best['multistart_first_s'], t['multistart16_s'])} |",
        f"| pyElli + scipy MINPACK LM, per fit (min / median; median {best['pyelli_nfev_median']:.0f} model "
        f"evaluations) | {best['pyelli_fit_min_s']:.3f} / {best['pyelli_fit_median_s']:.3f} s | "
        f"{best['pyelli_fit_median_cpu_s']:.3f} s (median) | {each('pyelli_fit_median_s', 1, 3)} s (medians) | — | — |",
        f"| pyElli per fit / layerstack further fit (medians) | "
        f"{best['pyelli_fit_median_s'] / best['further_fit_median_s']:.1f}× | "
        f"{best['pyelli_fit_median_cpu_s'] / best['further_fit_median_cpu_s']:.1f}× | | | |",
        "",
        "Agreement (every repeat of every process):",
        "",
        f"- layerstack ψ, Δ at the truth vs pyElli's: max |difference| "
        f"{max(r['model_check_deg'] for r in runs):.1e}° (≤ 1e-9° required).",
        f"- fitted values, layerstack vs pyElli: max |difference| "
        f"{max(r['max_disagreement_in_stderr'] for r in runs):.1e} standard errors (≤ {AGREEMENT_STDERR:g} required). "
        f"First data set: d = {d_ours[0]:.5f} / {d_elli[0]:.5f} nm, A = {d_ours[1]:.6f} / {d_elli[1]:.6f}, "
        f"B = {d_ours[2]:.7f} / {d_elli[2]:.7f} µm² (layerstack / pyElli; standard errors {se[0]:.2g} nm, "
        f"{se[1]:.2g}, {se[2]:.2g} µm²).",
        f"- against the truth (d = {TRUTH['d']:g} nm, A = {TRUTH['A']:g}, B = {TRUTH['B']:g} µm²): max "
        f"{max(r['max_error_in_stderr'] for r in runs):.2f} standard errors; every layerstack fit converged: "
        f"{all(r['all_converged'] for r in runs)}.",
        f"- multi-start: {best['multistart_converged'][0]}/{best['starts']} and {best['multistart_converged'][1]}/"
        f"{best['starts']} starts converged ({best['multistart_abandoned'][0]} and {best['multistart_abandoned'][1]} "
        "given up far above the best start: `fitting._multistart.give_up_rule`); the best start equals the single fit to "
        f"{max(r['multistart_vs_single_in_stderr'] for r in runs):.1e} standard errors "
        f"({best['multistart_steps'][0]} LM steps, as the single fit: the objective's own start wins).",
        "",
        "What is timed: layerstack's `fitting.fit` returns a full `FitResult` (covariance, correlations, "
        "identifiability, bound checks, fit-quality verdict); pyElli's row is the bare `least_squares` call. "
        "Both solve from the same start on the same data to the same optimum.",
        "",
        "Compilations (JAX's compile events; load does not change them), per process: "
        + "; ".join(f"first fit {r['compiles']['first_fit']['n']} (tracing {r['compiles']['first_fit']['trace_s']:.2f} s, "
                    f"XLA {r['compiles']['first_fit']['compile_s']:.2f} s wall), further fits "
                    f"{r['compiles']['further_fits']}, multi-start {r['compiles']['multistart_first']} then "
                    f"{r['compiles']['multistart']}" for r in runs) + ".",
    ]
    return lines + ["", "Where the time went before and after the changes of issue 15: "
                    "[ellipsometry_fit_history.md](ellipsometry_fit_history.md)."]


def _machine() -> dict:
    from benchmarks import _harness

    info = _harness.machine_info(with_jax_backend=False)
    try:
        from importlib.metadata import version

        info["pyelli"] = version("pyElli")
    except Exception:  # pragma: no cover
        info["pyelli"] = None
    return info


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.ellipsometry_fit", description=__doc__.split("\n")[0])
    p.add_argument("--processes", type=int, default=3, help="fresh processes; the best one is reported")
    p.add_argument("--repeats", type=int, default=10, help="further fits (and pyElli fits) per process")
    p.add_argument("--wavelengths", type=int, default=700)
    p.add_argument("--starts", type=int, default=16)
    p.add_argument("--out-dir", default=str(RESULTS))
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        print("RESULT " + json.dumps(run(a.wavelengths, a.repeats, a.starts)))
        return 0
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    machine = _machine()
    runs = []
    root = Path(__file__).resolve().parent.parent
    for k in range(a.processes):
        cmd = [sys.executable, "-m", "benchmarks.ellipsometry_fit", "--child", "--repeats", str(a.repeats),
               "--wavelengths", str(a.wavelengths), "--starts", str(a.starts)]
        out = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
        if out.returncode != 0:
            print(out.stderr[-4000:], file=sys.stderr)
            return 1
        line = next(s for s in out.stdout.splitlines() if s.startswith("RESULT "))
        runs.append(json.loads(line[len("RESULT "):]))
        r = runs[-1]
        print(f"process {k + 1}: first fit {r['first_fit_s']:.2f} s, further fit {1e3 * r['further_fit_median_s']:.1f} ms, "
              f"{a.starts} starts {r['multistart_s']:.2f} s, pyElli {r['pyelli_fit_median_s']:.3f} s", file=sys.stderr)
    best = dict(runs[0])  # every timing: the best (lowest) over the processes
    for key in TIMED:
        best[key] = min(r[key] for r in runs)
    # JAX's persistent compilation cache (what `layerstack fit` uses from its second run on): one
    # process fills a fresh cache, the next one's first fit loads the compiled program from it
    with tempfile.TemporaryDirectory() as cache:
        warm = []
        for _ in range(2):
            cmd = [sys.executable, "-m", "benchmarks.ellipsometry_fit", "--child", "--repeats", "1",
                   "--wavelengths", str(a.wavelengths), "--starts", "1"]
            out = subprocess.run(cmd, cwd=root, capture_output=True, text=True,
                                 env=dict(os.environ, E1_COMPILATION_CACHE=cache))
            if out.returncode != 0:
                print(out.stderr[-4000:], file=sys.stderr)
                return 1
            warm.append(json.loads(next(s for s in out.stdout.splitlines() if s.startswith("RESULT "))[len("RESULT "):]))
    best["warm_cache"] = {"first_fit_s": warm[1]["first_fit_s"], "first_fit_cpu_s": warm[1]["first_fit_cpu_s"],
                          "compiles": warm[1]["compiles"]["first_fit"], "filling_first_fit_s": warm[0]["first_fit_s"]}
    lines = markdown(best, runs, machine, uptime)
    out_dir = Path(a.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "ellipsometry_fit.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out_dir / "ellipsometry_fit.json").write_text(json.dumps({"machine": machine, "uptime": uptime, "runs": runs},
                                                              indent=1), encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
