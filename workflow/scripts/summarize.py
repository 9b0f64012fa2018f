#!/usr/bin/env python3
"""The workflow's summary across clips: summary.csv (one row per clip, every number), summary.md
(the same as tables, failures with herdfit's error lines) and summary.png (the held-out errors of
every clip side by side, and the fitted parameters).

    python3 summarize.py --results RESULTS --inputs FOLDER [--inputs FOLDER …] [--partial]

Each clip's status comes from the files on disk: `ok` (validation report and fit present),
`failed` (a step's output is missing and its log ends in herdfit's `error:` line, quoted), or
`not run` (no output and no log: an earlier step failed, or the run was stopped before it).
Without --partial (the summary job, whose inputs are every clip's report) anything but `ok` is an
error; with it (after a failed run) failures are listed. No times, hosts or absolute paths go into
the files, so two runs of the same inputs and settings write the same bytes wherever they ran.
Written atomically (temporary file, then rename).
"""

import argparse
import csv
import io
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import herdfit_wf  # noqa: E402

FORCES = ["cohesion", "avoidance", "alignment", "obstacle"]
PARTS = ["weight", "radial", "angular"]
PARAMS = [f"{f}.{p}" for f in FORCES for p in PARTS]
MEASURES = [
    "density_error", "velocity_error", "polarization", "angular_momentum_centroid",
    "angular_momentum_frame_centre", "aspect_ratio",
]
# Column names of the held-out errors (the report's measure -> error of that measure).
ERR_COLS = [m if m.endswith("_error") else m + "_error" for m in MEASURES]
COLUMNS = (
    ["clip", "kind", "input", "status", "failed_step", "error", "frames", "fit_frames",
     "heldout_frames", "seeds", "tracks", "boundary_entry_cells", "boundary_exit_cells"]
    + ERR_COLS
    + ["baseline_" + c for c in ERR_COLS]
    + ["fit_density_error_start", "fit_density_error_fitted", "fit_velocity_error_start",
       "fit_velocity_error_fitted", "determined_directions"]
    + PARAMS
)


def steps(clip):
    """(step, its output, its log) in order, relative to the results folder."""
    out = []
    rule = clip.ingest_rule()
    if rule:
        out.append((rule, f"clips/{clip.name}/clip.json", f"logs/{rule}/{clip.name}.log"))
    out.append(("fit", f"fits/{clip.name}/params.json", f"logs/fit/{clip.name}.log"))
    out.append(("validate", f"validation/{clip.name}/report.json", f"logs/validate/{clip.name}.log"))
    return out


def status(results, clip):
    """('ok'|'failed'|'not run', step, error line)."""
    for step, output, log in steps(clip):
        if os.path.isfile(os.path.join(results, output)):
            continue
        log = os.path.join(results, log)
        if os.path.isfile(log):
            return "failed", step, herdfit_wf.error_line(log) or "stopped before it finished (no error line in its log)"
        return "not run", step, ""
    return "ok", "", ""


def rows_of(report):
    """{measure: error mean} of each parameter set in a validation report, by set name."""
    return {
        s["name"]: {r["measure"]: r["error"]["mean"] for r in s["rows"]}
        for s in report["sets"]
    }


def clip_row(results, clip):
    st, step, err = status(results, clip)
    row = dict.fromkeys(COLUMNS, "")
    row.update(clip=clip.name, kind=clip.kind, input=clip.path, status=st, failed_step=step, error=err)
    if st != "ok":
        return row
    with open(os.path.join(results, f"fits/{clip.name}/params.json")) as f:
        params = json.load(f)
    with open(os.path.join(results, f"validation/{clip.name}/report.json")) as f:
        report = json.load(f)
    prov = params.get("provenance", {})
    fit_frames = prov.get("frames") or ["", ""]
    sets = rows_of(report)
    fitted = sets.get("fitted") or next(iter(sets.values()))
    baseline = sets.get("baseline", {})
    ev = prov.get("evaluation", {})
    unc = params.get("uncertainty") or {}
    # validate --boundary auto: the gates found from the video's edge flux; none = a closed clip.
    gates = (report.get("boundary") or {}).get("gates") or {}
    row.update(
        frames=report["frames"][1],
        fit_frames=f"{fit_frames[0]}..{fit_frames[1]}",
        heldout_frames=f"{report['frames'][0]}..{report['frames'][1]}",
        seeds=report["seeds"],
        tracks="yes" if report.get("tracks") else "no",
        boundary_entry_cells=len(gates.get("entries", [])),
        boundary_exit_cells=len(gates.get("exits", [])),
        fit_density_error_start=ev.get("start", {}).get("density_error", ""),
        fit_density_error_fitted=ev.get("fitted", {}).get("density_error", ""),
        fit_velocity_error_start=ev.get("start", {}).get("velocity_error", ""),
        fit_velocity_error_fitted=ev.get("fitted", {}).get("velocity_error", ""),
        determined_directions=(
            sum(1 for d in unc.get("directions", []) if d.get("determined")) if unc else ""
        ),
    )
    for m, c in zip(MEASURES, ERR_COLS):
        row[c] = fitted.get(m, "")
        row["baseline_" + c] = baseline.get(m, "")
    for name in PARAMS:
        force, part = name.split(".")
        row[name] = params["forces"][force][part]
    return row


def fmt(v, digits=4):
    return f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def write_atomic(path, data):
    tmp = f"{path}.part-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def csv_bytes(rows):
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue().encode()


def md_bytes(rows, version):
    ok = [r for r in rows if r["status"] == "ok"]
    bad = [r for r in rows if r["status"] != "ok"]
    out = [
        "# herdfit: many clips",
        "",
        f"{len(rows)} clips: {len(ok)} fitted and validated, {len(bad)} not ({version}). Held-out "
        "errors of the fitted set, each the mean over the held-out frames and the seeds "
        "(`validate`; density and velocity relative, the measures |simulation − video|); fit: "
        "density and velocity error at the start and fitted set on the fit's own frames; "
        "tracks: fitted and validated from the tracked animals; boundary: entry/exit cells of "
        "the open boundary found from the video (`--boundary auto`), or closed.",
        "",
        "| clip | kind | status | fit frames | held-out | tracks | boundary | density | velocity "
        "| polarization "
        "| ang. mom. centroid | ang. mom. centre | aspect ratio | fit density start → fitted "
        "| fit velocity start → fitted | determined |",
        "|---|---|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["status"] != "ok":
            out.append(f"| {r['clip']} | {r['kind']} | {r['status']} ({r['failed_step']}) |"
                       + " |" * 13)
            continue
        fit_d = f"{fmt(r['fit_density_error_start'])} → {fmt(r['fit_density_error_fitted'])}"
        fit_v = f"{fmt(r['fit_velocity_error_start'])} → {fmt(r['fit_velocity_error_fitted'])}"
        det = f"{r['determined_directions']}/12" if r["determined_directions"] != "" else "—"
        ins, outs = r["boundary_entry_cells"], r["boundary_exit_cells"]
        boundary = f"{ins} in, {outs} out" if ins or outs else "closed"
        out.append(
            f"| {r['clip']} | {r['kind']} | ok | {r['fit_frames']} | {r['heldout_frames']} | "
            f"{r['tracks']} | {boundary} | "
            + " | ".join(fmt(r[c]) for c in ERR_COLS)
            + f" | {fit_d} | {fit_v} | {det} |"
        )
    if any(r["baseline_density_error"] != "" for r in ok):
        out += ["", "Baseline (the start set, `validate --baseline`), same errors:", "",
                "| clip | " + " | ".join(ERR_COLS) + " |", "|---|" + "---:|" * len(ERR_COLS)]
        for r in ok:
            out.append(f"| {r['clip']} | " + " | ".join(fmt(r["baseline_" + c]) for c in ERR_COLS) + " |")
    if ok:
        out += ["", "Fitted parameters:", "", "| clip | " + " | ".join(PARAMS) + " |",
                "|---|" + "---:|" * len(PARAMS)]
        for r in ok:
            out.append(f"| {r['clip']} | " + " | ".join(fmt(r[p], 3) for p in PARAMS) + " |")
    if bad:
        out += ["", "Not fitted:", ""]
        for r in bad:
            why = f": `{r['error']}`" if r["error"] else " (an earlier step failed or the run stopped)"
            out.append(f"- **{r['clip']}** ({r['input']}) — {r['status']} at {r['failed_step']}{why}")
    out += ["", "Files: `summary.csv` (every number, full precision), `summary.png`; per clip "
            "`fits/CLIP/` (parameters, training log, loss curve), `validation/CLIP/` (report), "
            "`logs/STEP/CLIP.log`.", ""]
    return "\n".join(out).encode()


def png_bytes(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r["clip"] for r in rows]
    ok = [r["status"] == "ok" for r in rows]
    fig = plt.figure(figsize=(12, 8.5))
    grid = fig.add_gridspec(3, 3, height_ratios=[1, 1, 1.1], hspace=0.75, wspace=0.3)
    x = list(range(len(rows)))
    for k, (m, c) in enumerate(zip(MEASURES, ERR_COLS)):
        ax = fig.add_subplot(grid[k // 3, k % 3])
        vals = [r[c] if good else 0.0 for r, good in zip(rows, ok)]
        ax.bar(x, vals, color="#4c72b0")
        if any(r["baseline_" + c] != "" for r in rows):
            ax.plot(x, [r["baseline_" + c] if r["baseline_" + c] != "" else float("nan") for r in rows],
                    "o", color="#dd8452", label="baseline")
            ax.legend(fontsize=7)
        top = max(vals + [1e-9])
        for i, good in enumerate(ok):
            if not good:
                ax.text(i, top * 0.05, "failed", rotation=90, ha="center", va="bottom", color="#c44e52", fontsize=8)
        ax.set_title(m.replace("_", " ") + (" error" if not m.endswith("error") else ""), fontsize=9)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=45, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
    ax = fig.add_subplot(grid[2, :])
    table = [[r[p] if good else float("nan") for p in PARAMS] for r, good in zip(rows, ok)]
    im = ax.imshow(table, aspect="auto", vmin=0, vmax=1, cmap="viridis", interpolation="nearest")
    ax.set_xticks(range(len(PARAMS)))
    ax.set_xticklabels(PARAMS, rotation=30, ha="right", fontsize=7)
    ax.set_yticks(x)
    ax.set_yticklabels(names, fontsize=7)
    ax.set_title("fitted parameters (blank: failed)", fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.02, pad=0.01)
    fig.suptitle("herdfit: held-out errors of the fitted set per clip", fontsize=11)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def herdfit_version(binary):
    import subprocess

    try:
        return subprocess.run([binary, "--version"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "herdfit (version unknown)"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", required=True)
    ap.add_argument("--inputs", action="append", required=True)
    ap.add_argument("--herdfit", default="herdfit")
    ap.add_argument("--partial", action="store_true")
    a = ap.parse_args()
    try:
        clips = herdfit_wf.discover(a.inputs)
    except herdfit_wf.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    rows = [clip_row(a.results, clips[n]) for n in sorted(clips)]
    bad = [r for r in rows if r["status"] != "ok"]
    if bad and not a.partial:
        r = bad[0]
        print(f"error: {r['clip']}: {r['status']} at {r['failed_step']} {r['error']}".rstrip(), file=sys.stderr)
        return 1
    # All three made before any is written: a failure leaves the previous summary whole.
    files = {
        "summary.csv": csv_bytes(rows),
        "summary.md": md_bytes(rows, herdfit_version(a.herdfit)),
        "summary.png": png_bytes(rows),
    }
    os.makedirs(a.results, exist_ok=True)
    for name, data in files.items():
        write_atomic(os.path.join(a.results, name), data)
    print(f"summary: {len(rows) - len(bad)} of {len(rows)} clips ok; wrote {a.results}/summary.csv, .md, .png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
