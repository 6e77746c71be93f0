"""Short campaigns whose decisions must not change when the code around them is reorganised.

    python benchmarks/compare_decisions.py --json OUT.json [--compare BEFORE.json]

Runs, in this process and without Prefect, a few BO steps of: Forrester seeds 0-2 under the
policies reward and double, PFM (data/configs/pfm.yaml) seed 0, Branin seed 0, a budgeted
info_rate campaign, and Forrester campaigns with the noise laws power and quadrature (the latter
also with a noise field, data/configs/forrester_patch.yaml), the posterior convergence rule
(data/configs/forrester_posterior.yaml) with noise_t informative and, in the budget mode, valued,
and an info_rate campaign in the budget mode over Branin's two axes. Writes every point (x, t, value,
noise, shots), every decision's proposal, acquisition value, predicted optimal t and noise at t,
and the final predicted optimal t, as exact floats (``float.hex``). ``--compare`` reads an earlier
file and exits 1 naming the first difference, 0 when every number is identical.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from noisebo.instruments import build  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import CampaignConfig, load_config  # noqa: E402

CONFIGS = ROOT / "data" / "configs"


def campaigns() -> list[tuple[str, CampaignConfig, int]]:
    forrester = load_config(CONFIGS / "forrester.yaml").with_overrides(
        space={"n_x": 60, "n_t": 40}, schedule={"n_steps": 6}
    )
    out = [
        (f"forrester-{policy}-s{seed}", forrester.with_overrides(acquisition={"policy": policy}), seed)
        for policy in ("reward", "double")
        for seed in range(3)
    ]
    out.append(("pfm-s0", load_config(CONFIGS / "pfm.yaml").with_overrides(schedule={"n_steps": 3}), 0))
    out.append(("branin-s0", load_config(CONFIGS / "branin.yaml").with_overrides(schedule={"n_steps": 3}), 0))
    out.append(
        (
            "forrester-info_rate-budget-s0",
            forrester.with_overrides(acquisition={"policy": "info_rate"}, schedule={"n_steps": 10, "budget_s": 400.0}),
            0,
        )
    )
    out.append(
        (
            "forrester-power-s0",
            forrester.with_overrides(noise_model={"mean": "power"}, acquisition={"policy": "double"}),
            0,
        )
    )
    out.append(("forrester-quadrature-s0", forrester.with_overrides(noise_model={"mean": "quadrature"}), 0))
    out.append(
        (
            "forrester_patch-quadrature-field-s0",
            load_config(CONFIGS / "forrester_patch.yaml").with_overrides(
                space={"n_x": 60, "n_t": 40}, schedule={"n_steps": 3}
            ),
            0,
        )
    )
    posterior = load_config(CONFIGS / "forrester_posterior.yaml").with_overrides(
        space={"n_x": 60, "n_t": 40}, schedule={"n_steps": 6}
    )
    out.append(("forrester_posterior-informative-s0", posterior, 0))
    out.append(
        (
            "forrester_posterior-valued-budget-s0",
            posterior.with_overrides(schedule={"mode": "budget", "noise_t": "valued", "budget_s": 300.0}),
            0,
        )
    )
    out.append(
        (
            "branin-info_rate-budget_mode-s0",
            load_config(CONFIGS / "branin.yaml").with_overrides(
                acquisition={"policy": "info_rate"}, schedule={"mode": "budget", "n_steps": 4, "budget_s": 200.0}
            ),
            0,
        )
    )
    return out


def exact(value) -> str:
    return float(value).hex()


def record(config: CampaignConfig, seed: int) -> dict:
    run = run_campaign(config, build(config.instrument), seed)
    points = [
        {
            "x": [exact(v) for v in p.x],
            "t": exact(p.t),
            "value": exact(p.value),
            "noise": exact(p.noise),
            "shots": p.n_shots,
        }
        for p in run.state.points
    ]
    decisions = [
        {
            "step": d.step,
            "x": [exact(v) for v in d.x],
            "t": exact(d.t),
            "acq_value": exact(d.acq_value),
            "shots": d.shots,
            "t_opt": exact(d.t_opt),
            "noise_at_t": exact(d.noise_at_t),
            "converged": d.converged,
        }
        for d in run.decisions
    ]
    final = run.summary.t_opt if run.summary is not None else run.decisions[-1].t_opt
    return {"points": points, "decisions": decisions, "final_t_opt": exact(final)}


def first_difference(before, after, where: str = "") -> str | None:
    if isinstance(before, dict) and isinstance(after, dict):
        for key in sorted(set(before) | set(after)):
            if key not in before or key not in after:
                return f"{where}.{key}: present in one file only"
            found = first_difference(before[key], after[key], f"{where}.{key}")
            if found:
                return found
        return None
    if isinstance(before, list) and isinstance(after, list):
        if len(before) != len(after):
            return f"{where}: {len(before)} entries before, {len(after)} after"
        for k, (a, b) in enumerate(zip(before, after)):
            found = first_difference(a, b, f"{where}[{k}]")
            if found:
                return found
        return None
    return None if before == after else f"{where}: {before!r} before, {after!r} after"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", type=Path, required=True)
    parser.add_argument("--compare", type=Path, default=None)
    parser.add_argument("--only", default=None, help="run only the campaigns whose name contains this")
    args = parser.parse_args(argv)
    out = {}
    for name, config, seed in campaigns():
        if args.only and args.only not in name:
            continue
        out[name] = record(config, seed)
        last = out[name]["decisions"][-1] if out[name]["decisions"] else {}
        print(
            f"{name}: {len(out[name]['points'])} points, final t_opt {float.fromhex(out[name]['final_t_opt']):.6g} s"
            + (f", last acq {float.fromhex(last['acq_value']):.6g}" if last else ""),
            flush=True,
        )
    args.json.write_text(json.dumps(out, indent=1))
    if args.compare is None:
        return 0
    before = json.loads(args.compare.read_text())
    if args.only:
        before = {k: v for k, v in before.items() if k in out}
    problem = first_difference(before, out)
    print("identical: every point, decision and final t_opt" if problem is None else f"DIFFERENT: {problem}")
    return 0 if problem is None else 1


if __name__ == "__main__":
    raise SystemExit(main())
