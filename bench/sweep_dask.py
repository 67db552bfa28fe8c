"""What a sweep costs: in-process against a bare simulate_batch, and on Dask workers.

10,000 runs of the double pendulum over 10 s (dop853, rtol 1e-8, atol 1e-10,
101 samples), a 100 x 100 grid of m2 and the release angle q1:

(a) ``modelgen.sweep`` in-process against a bare ``cm.simulate_batch`` of the
    same runs (target: within 10%), and the same sweep of a scene with 35
    output columns (evaluated per sample after the C run);
(b) a ``LocalCluster`` of 1 and of 2 single-threaded worker processes
    (target: 2 workers >= 1.6x one), the cluster started and the model loaded
    on the workers before the clock starts;
(c) runs per second against the chunk size on 2 workers, and the scheduler's
    overhead per chunk (near-empty runs, one per chunk).

Every sweep on the cluster is compared with the in-process one (the largest
difference of q2 over all runs and samples; 0 when the workers computed what
the process did), so the speed-up is of the same work.

Prints the tables, the machine's load average, and writes docs/sweep_dask.md
and docs/sweep_dask.png.  Usage::

    python bench/sweep_dask.py [--runs 10000] [--out docs]

The machine may be shared: the load average before and after is printed
with the figures (on 2 cores, a load above 2 takes cores from the workers).
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(HERE))
os.environ["PYTHONPATH"] = os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])

import numpy as np                                     # noqa: E402

import modelgen                                        # noqa: E402

T_END = 10.0
T_EVAL = np.linspace(0.0, T_END, 101)
SETTINGS = dict(method="dop853", rtol=1e-8, atol=1e-10)


def load_average() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def interleaved(fns: dict, repeats: int) -> dict:
    """name -> (min wall s, min CPU s of this process, last result), the functions
    taking turns in every repeat so a change in the machine's load hits them alike."""
    out = {name: [np.inf, np.inf, None] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            wall, cpu = time.perf_counter(), time.process_time()
            result = fn()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            best = out[name]
            best[0], best[1], best[2] = min(best[0], wall), min(best[1], cpu), result
    return {name: tuple(v) for name, v in out.items()}


def study(runs: int) -> dict:
    side = int(round(np.sqrt(runs)))
    return modelgen.grid(m2=np.linspace(0.5, 2.0, side), q1=np.linspace(0.1, 3.0, runs // side))


def in_process(cm, scene, g, repeats) -> list:
    n = g["m2"].size
    X0 = np.column_stack([g["q1"], np.full(n, 0.5), np.zeros(n), np.zeros(n)])
    modelgen.sweep(cm, {"m2": g["m2"][:2]}, t_eval=T_EVAL, **SETTINGS)  # imports xarray
    swept = ({"m2": g["m2"]}, {"q1": g["q1"]})
    ny = len(scene.model.output_columns)
    runs = interleaved({
        "bare cm.simulate_batch": lambda: cm.simulate_batch(
            X0, (0.0, T_END), t_eval=T_EVAL, P={"m2": g["m2"]}, **SETTINGS),
        "modelgen.sweep (model)": lambda: modelgen.sweep(
            cm, *swept, t_eval=T_EVAL, x0=X0[0], **SETTINGS)}, repeats)
    runs.update(interleaved({
        "sweep of the scene, outputs=False": lambda: modelgen.sweep(
            scene, *swept, t_eval=T_EVAL, x0=X0[0], outputs=False, **SETTINGS),
        f"sweep of the scene, {ny} output columns": lambda: modelgen.sweep(
            scene, *swept, t_eval=T_EVAL, x0=X0[0], **SETTINGS)}, 1))
    ref, ds = runs["bare cm.simulate_batch"][2], runs["modelgen.sweep (model)"][2]
    assert np.array_equal(ds["q2"].values, ref.y[:, 1, :], equal_nan=True)
    wall, cpu = runs["bare cm.simulate_batch"][:2]
    return [(name, n, w, w / wall, c, c / cpu) for name, (w, c, _) in runs.items()], ds


def difference(ds, reference) -> float:
    """The largest difference of q2 between two sweeps of the same runs (0.0: the
    cluster computed what the process did)."""
    a, b = ds["q2"].values, reference["q2"].values
    if a.shape != b.shape:
        return float("inf")
    return float(np.nanmax(np.abs(a - b))) if np.isfinite(a).any() else float("inf")


def cluster_rows(cm, g, workers_list, chunks, overhead_chunks, reference) -> tuple:
    from distributed import Client, LocalCluster
    rows, chunk_rows, overhead = [], [], None
    n = g["m2"].size
    x0 = [0.0, 0.5, 0.0, 0.0]
    for workers in workers_list:
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            # warm up: every worker imports modelgen and loads the model once
            modelgen.sweep(cm, {"m2": g["m2"][:8 * workers]}, {"q1": g["q1"][:8 * workers]},
                           t_eval=T_EVAL, x0=x0, client=client, chunk=1, **SETTINGS)
            cpu0 = client.run(time.process_time)
            ds = modelgen.sweep(cm, {"m2": g["m2"]}, {"q1": g["q1"]}, t_eval=T_EVAL, x0=x0,
                                client=client, **SETTINGS)
            cpu = [t - cpu0[w] for w, t in client.run(time.process_time).items()]
            rows.append((workers, ds.attrs["chunk"], ds.attrs["seconds"],
                         n / ds.attrs["seconds"], ds.attrs["compute_seconds"], max(cpu),
                         difference(ds, reference)))
            print(f"  {workers} worker(s): {ds.attrs['seconds']:.2f} s (load {load_average()})",
                  flush=True)
            if workers == max(workers_list):
                for chunk in chunks:
                    ds = modelgen.sweep(cm, {"m2": g["m2"]}, {"q1": g["q1"]}, t_eval=T_EVAL,
                                        x0=x0, client=client, chunk=chunk, **SETTINGS)
                    chunk_rows.append((chunk, ds.attrs["chunks"], ds.attrs["seconds"],
                                       n / ds.attrs["seconds"], difference(ds, reference)))
                    print(f"  chunk {chunk}: {ds.attrs['seconds']:.2f} s", flush=True)
                # near-empty runs, one per chunk: what remains is the scheduler's cost
                k = overhead_chunks
                ds = modelgen.sweep(cm, {"m2": np.ones(k)}, t_eval=[0.0, 1e-6], x0=x0,
                                    client=client, chunk=1, **SETTINGS)
                overhead = (k, ds.attrs["seconds"], ds.attrs["compute_seconds"],
                            ds.attrs["seconds"] / k * workers)
    return rows, chunk_rows, overhead


def table(header, rows, formats) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---:|" * len(header)]
    lines += ["| " + " | ".join(f.format(v) for f, v in zip(formats, row)) + " |"
              for row in rows]
    return "\n".join(lines)


def figure(cluster, chunk_rows, serial_rate, serial_cpu_rate, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(8, 3.2), layout="constrained")
    w = [r[0] for r in cluster]
    n = cluster[0][3] * cluster[0][2]
    a.plot(w, [r[3] for r in cluster], "o-", label="LocalCluster, wall time")
    a.plot(w, [n / r[5] for r in cluster], "s-", label="per CPU s of the busiest worker")
    a.plot(w, [serial_cpu_rate * k for k in w], "k--", lw=0.8,
           label="in-process per CPU s x workers")
    a.set_xlabel("workers (1 thread each)")
    a.set_ylabel("runs per second")
    a.set_xticks(w)
    a.set_ylim(bottom=0)
    a.legend(fontsize=8)
    b.semilogx([r[0] for r in chunk_rows], [r[3] for r in chunk_rows], "o-")
    b.axhline(serial_rate, color="k", ls=":", lw=0.8, label="in-process (wall time)")
    b.set_xlabel(f"runs per chunk ({w[-1]} workers)")
    b.set_ylabel("runs per second (wall time)")
    b.legend(fontsize=8)
    fig.suptitle("double pendulum, 10 s, dop853 rtol 1e-8: sweeps on Dask", fontsize=10)
    fig.savefig(path, dpi=80)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default=str(HERE / "docs"))
    args = parser.parse_args(argv)
    missing = [m for m in ("distributed", "xarray") if importlib.util.find_spec(m) is None]
    if missing:
        print(f"{' and '.join(missing)} not installed: the sweeps on Dask cannot run "
              "(pip install '.[sweep]')", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    build = Path(os.environ.get("MODELGEN_CACHE_DIR", "/tmp")) / "bench_sweep"
    cm = modelgen.load(HERE / "models" / "double_pendulum.yaml", build / "dp")
    scene = modelgen.load_scene(HERE / "models" / "scenes" / "dp_free.yaml", build / "dp_free")
    g = study(args.runs)
    n = g["m2"].size
    load_before = load_average()
    print(f"{n} runs, {os.cpu_count()} cores, load average {load_before}", flush=True)
    serial, reference = in_process(cm, scene, g, args.repeats)
    t1 = table(["what", "runs", "wall s", "ratio to bare", "CPU s", "ratio to bare"], serial,
               ["{}", "{}", "{:.2f}", "{:.3f}", "{:.2f}", "{:.3f}"])
    print(t1, flush=True)
    chunk_sizes = [n // 2, n // 8, n // 32, n // 128, max(n // 512, 1)]
    cluster, chunk_rows, overhead = cluster_rows(cm, g, [1, 2], chunk_sizes, 200, reference)
    t2 = table(["workers", "runs per chunk", "wall s", "runs/s", "chunks' wall s (sum)",
                "busiest worker's CPU s", "q2 difference to in-process"],
               cluster, ["{}", "{}", "{:.2f}", "{:.0f}", "{:.2f}", "{:.2f}", "{:.1e}"])
    speedup = cluster[0][2] / cluster[-1][2]
    cpu_speedup = cluster[0][5] / cluster[-1][5]
    t3 = table(["runs per chunk", "chunks", "seconds", "runs/s", "q2 difference to in-process"],
               chunk_rows, ["{}", "{}", "{:.2f}", "{:.0f}", "{:.1e}"])
    k, secs, compute, per_chunk = overhead
    load_after = load_average()
    lines = [
        "# Sweeps on Dask: measured by bench/sweep_dask.py",
        "",
        f"{n} runs of the double pendulum over 10 s (dop853, rtol 1e-8, atol 1e-10, 101 "
        f"samples), a grid of m2 and q1; {os.cpu_count()} cores, load average "
        f"{load_before} before and {load_after} after (1, 5, 15 min; the machine is shared).",
        "",
        "In-process (min of repeats, taking turns; CPU: this process's time, less "
        "sensitive to the other jobs on the machine):", "", t1, "",
        "LocalCluster, single-threaded worker processes, default chunks (4 per worker), "
        "cluster started and model loaded before timing:", "", t2, "",
        f"2 workers / 1 worker: {speedup:.2f}x in wall time (target >= 1.6x); "
        f"{cpu_speedup:.2f}x in the busiest worker's CPU time (the speed-up with both "
        f"cores free: how evenly and cheaply the work splits).", "",
        "Runs per second against the chunk size (2 workers):", "", t3, "",
        f"Scheduler overhead: {k} near-empty runs, one per chunk, took {secs:.2f} s on 2 "
        f"workers ({compute * 1e3:.1f} ms inside the chunks): {per_chunk * 1e3:.1f} ms per "
        f"chunk per worker.", "",
        "![runs per second against workers and chunk size](sweep_dask.png)", ""]
    text = "\n".join(lines)
    print(text)
    (out / "sweep_dask.md").write_text(text)
    figure(cluster, chunk_rows, n / serial[1][2], n / serial[1][4], out / "sweep_dask.png")
    print(f"wrote {out / 'sweep_dask.md'} and {out / 'sweep_dask.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
