"""What the reports of bench/ms_lamp_height.sh and bench/ms_spot.sh share: the grid's rows from
ms_compare.py, the summary of their median errors, and the cost runs' medians with the solve's
own times (ms_lib.sh's lamp_cost writes both files)."""
import json
import statistics as st


def grid(path):
    """The rows of a grid file (one JSON object a line)."""
    return [json.loads(l) for l in open(path) if l.strip()]


def summary(rows):
    """Prints the median of the per-case median errors, the worst, and Cycles' noise."""
    med = [r["rel_median"] for r in rows]
    print("- %d cases: median of the per-case median errors %.2f %% (worst %.2f %%); Cycles' noise per block median %.2f %%" % (
        len(rows), 100 * st.median(med), 100 * max(med), 100 * st.median(r["noise_rel_median"] for r in rows)))


def costs(cost_path, solve_path):
    """Median wall time per KEY/RUN, the solve's seconds per KEY, and the KEYs in order."""
    cost = {}
    for l in open(cost_path):
        k, v = l.rsplit(" ", 1)
        cost.setdefault(k, []).append(float(v))
    m = {k: st.median(v) for k, v in cost.items()}
    solve = {k: float(v.split()[0]) for k, v in
             (l.strip().split("/solve ") for l in open(solve_path) if "/solve " in l)}
    return m, solve, sorted({k.rsplit("/", 1)[0] for k in m})


def case_cells(r):
    """A lamp case's cells after its description (bench/ms_lamp_box.sh, ms_lamp_layered.sh):
    density, albedo, g, the single share, its check, the errors, noise, error output, coverage
    and the multiple part's ratio."""
    return "%g | %g | %g | %.3f | %+.2f %% | %.2f %% | %.2f %% | %+.2f %% | %.2f %% | %.2e | %.0f %% | %.3f |" % (
        r["density"], r["albedo"], r["g"], r["single_share_median"],
        100 * r["single_check_median"], 100 * r["rel_median"], 100 * r["rel_p99"],
        100 * r["rel_signed_median"], 100 * r["noise_rel_median"], r["err_rel_median"],
        100 * r["covered"], ms_ratio(r))


def cost_table(title, cost_path, solve_path):
    """Prints lamp_cost's medians (bench/ms_lib.sh) under TITLE: single against multiple per
    fog, and the solve."""
    print("### " + title)
    print()
    m, solve, fogs = costs(cost_path, solve_path)
    print("| fog | single s | multiple s | / single | the solve (once per scene) |")
    print("|---|---:|---:|---:|---:|")
    for fog in fogs:
        s1, sm = m[fog + "/single"], m[fog + "/multiple"]
        print("| `%s` | %.2f | %.2f | %.2fx | %.2f s |" % (fog, s1, sm, sm / s1, solve.get(fog, 0.0)))


def ms_ratio(r):
    """The multiple scattering alone over the frame, exrfog's over Cycles' (multiple less single
    against 128 bounces less 0)."""
    ms_e = r["exrfog_multiple_mean"] - r["exrfog_single_mean"]
    ms_c = r["cycles_mean"] - r["cycles_single_mean"]
    return ms_e / ms_c if ms_c > 0 else float("nan")
