"""``kinlearn reproduce``: the whole pipeline, side by side with the paper.

babble → FM/IM → endpoint pairs → TM for the paper's six optimiser configurations (Table 1) over
several seeds → evaluation on held-out pairs (Table 2) → the ablation (learned/analytic FM × IM) →
the reference-parity row → the baselines → the workspace task (joint-path TMs trained through the
learned and the analytic FM, judged on held-out pairs across the joint range with joint goals and
with end-effector position goals, beside the baselines) → ``results.md``, ``results.json`` and the
figures.

The sweep runs as independent jobs (:func:`_job`) on local worker processes, or as Ray tasks
(``backend="ray"``), through :func:`kinlearn.evaluation.jobs.run_jobs`.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import torch

from ..body.robot import load_robot
from ..data.babbling import BabblingConfig, babble
from ..data.endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from ..data.problem import Problem
from ..errors import ConfigError, DomainWarning, MissingDependencyError, TrainingDivergedError
from ..io import write_json
from ..models.forward_inverse import fm_config, im_config
from ..planning import registry
from ..planning.planner import Planner
from ..training.forward_inverse import train_config, train_fm, train_im, train_im_distal, validate_models
from ..training.imitation import train_imitation
from ..training.tm import TMTrainConfig, tm_preset, train_tm
from ..training.tm_seeds import train_tm_seeds
from .jobs import run_jobs
from .metrics import METRICS, PAPER_TABLE2, TABLE2_COLUMNS, format_table, plan_metrics, summarize

__all__ = ["OPTIMIZER_SWEEP", "REPRODUCE_PRESETS", "ReproduceConfig", "evaluate_plans", "reproduce"]

#: The paper's Table 1: optimiser configurations and their reported final L_TM.
OPTIMIZER_SWEEP: dict[int, dict] = {
    1: {"optim": {"name": "adam", "lr": 1e-3}, "paper_l_tm": 0.084},
    2: {"optim": {"name": "adam", "lr": 1e-4}, "paper_l_tm": 0.170},
    3: {"optim": {"name": "rmsprop", "lr": 1e-2, "alpha": 0.99}, "paper_l_tm": 0.040},
    4: {"optim": {"name": "rmsprop", "lr": 1e-3, "alpha": 0.99}, "paper_l_tm": 0.017},
    5: {"optim": {"name": "sgd", "lr": 0.5}, "paper_l_tm": 0.034},
    6: {"optim": {"name": "sgd", "lr": 1.0}, "paper_l_tm": 0.048},
}


@dataclass(frozen=True)
class ReproduceConfig:
    """Sizes of every stage. See :data:`REPRODUCE_PRESETS` for ``smoke``, ``quick`` and ``full``."""

    robot: str = "iiwa14"
    transitions: int = 500_000
    model_preset: str = "improved"  # FM/IM architecture and training preset
    model_epochs: int | None = None  # override the preset's epochs
    distal_epochs: int = 12  # refinement of the IM through the frozen FM (0: none)
    train_pairs: int = 12_000
    heldout_pairs: int = 2_000
    tm_epochs: int = 50
    tm_batch_size: int = 64
    seeds: tuple[int, ...] = tuple(range(10))
    sweep_loss: str = "paper"  # the loss of the Table 1 sweep
    parity_pairs: int = 12_000
    parity_epochs: int = 50
    workers: int = 2
    backend: Literal["local", "ray"] = "local"
    seed: int = 0
    workspace_iterations: int = 6000  # joint-path TM training iterations (0: skip the workspace task)
    workspace_batch_size: int = 512
    workspace_pairs: int = 2_000  # held-out workspace pairs (uniform within ±90% of the joint range)
    identify_samples: int = 60_000  # babbled states a chain is identified from, 1 mm noise (0: no chain)
    identify_mlp_steps: int = 1500  # the first MLP of its identification without a URDF


REPRODUCE_PRESETS: dict[str, dict] = {
    "smoke": {
        "transitions": 20_000,
        "model_preset": "tiny",
        "distal_epochs": 1,
        "train_pairs": 96,
        "heldout_pairs": 64,
        "tm_epochs": 2,
        "tm_batch_size": 32,
        "seeds": (0,),
        "parity_pairs": 8,
        "parity_epochs": 1,
        "workers": 1,
        "workspace_iterations": 4,
        "workspace_batch_size": 16,
        "workspace_pairs": 32,
        "identify_samples": 4000,
        "identify_mlp_steps": 100,
    },
    "quick": {
        "transitions": 300_000,
        "model_epochs": 6,
        "distal_epochs": 4,
        "train_pairs": 4_000,
        "heldout_pairs": 1_000,
        "tm_epochs": 20,
        "tm_batch_size": 64,
        "seeds": (0, 1),
        "parity_pairs": 500,
        "parity_epochs": 5,
        "workspace_iterations": 400,
        "workspace_batch_size": 256,
        "workspace_pairs": 1_000,
        "identify_samples": 30_000,
    },
    # Paper sizes: 500k babbling transitions (Cibula et al., ICANN 2024, Sect. 4.1), 12,000 + 2,000 pairs, 50 TM epochs,
    # 10 seeds. Shortened to fit an hour on 2 cores: FM/IM epochs, the batch-1 reference-parity run
    # (1,000 of the 12,000 pairs, all 50 epochs) and the workspace TMs' iterations.
    "full": {
        "model_epochs": 12,
        "distal_epochs": 4,
        "parity_pairs": 1_000,
        "workspace_iterations": 1_500,
    },
}


def evaluate_plans(plan, robot) -> dict:
    """Summary of :func:`kinlearn.evaluation.metrics.plan_metrics` over a batch of plans."""
    return summarize(plan_metrics(plan, robot))


def _evaluate_run(name: str, run_dir: Path, heldout, wall: float) -> dict:
    with open(run_dir / "metrics.jsonl") as fh:
        last = json.loads(fh.read().splitlines()[-1])
    planner = Planner.load(run_dir)
    # Held-out pairs outside the training pairs' range are part of the experiment, not something its user
    # can act on: recorded with the run's results instead of printed as warnings.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = planner.plan(heldout.start, heldout.goal)
    notes = []
    for w in caught:
        if issubclass(w.category, DomainWarning):
            notes.append(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    summary = evaluate_plans(plan, planner.robot)
    return {
        "name": name,
        "final_l_tm": last["train/paper_l_tm"],
        "final_loss": last["train/loss"],
        "train_seconds": wall,
        "heldout": summary,
        "domain_notes": notes,
    }


def _job(job: dict) -> list[dict]:
    """Run one training job (in a worker process); returns one result per trained model.

    Kinds: ``tm`` (one TM, evaluated on the held-out pairs), ``seeds`` (one TM configuration for
    several seeds in lockstep, each evaluated) and ``path`` (a joint-path TM for the workspace task,
    evaluated later by the caller)."""
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    if job["kind"] == "path":
        from ..training.joint_path import PathTrainConfig, train_path_model

        train_path_model(PathTrainConfig.from_dict(job["config"]), job["run_dir"], progress=False)
        return [{"name": job["name"], "train_seconds": time.perf_counter() - t0}]
    cfg = TMTrainConfig.from_dict(job["config"])
    train = load_endpoints(job["train"], robot=cfg.robot)
    if job.get("limit"):
        train = train.split(job["limit"])[0]
    heldout = load_endpoints(job["heldout"], robot=cfg.robot)
    if job["kind"] == "seeds":
        runs = train_tm_seeds(cfg, job["seeds"], job["run_dirs"], train, progress=False)
        wall = (time.perf_counter() - t0) / len(runs)  # the lockstep run's time, shared out
        out = []
        for (seed, run), name, run_dir in zip(runs.items(), job["names"], job["run_dirs"], strict=True):
            if isinstance(run, TrainingDivergedError):
                out.append({"name": name, "seed": seed, "diverged": str(run), "train_seconds": wall})
            else:
                out.append({"seed": seed, **_evaluate_run(name, Path(run_dir), heldout, wall)})
        return out
    run_dir = Path(job["run_dir"])
    try:
        train_tm(cfg, run_dir, train, progress=False)
    except TrainingDivergedError as exc:
        return [{"name": job["name"], "diverged": str(exc), "train_seconds": time.perf_counter() - t0}]
    return [_evaluate_run(job["name"], run_dir, heldout, time.perf_counter() - t0)]


def _mean_std(values: list[float]) -> dict:
    t = torch.tensor(values, dtype=torch.float64)
    return {"mean": float(t.mean()), "std": float(t.std(unbiased=False)) if len(values) > 1 else 0.0}


def _merge(summaries: list[dict]) -> dict:
    """Average per-seed summaries: each metric's mean of the seeds' means, the mean of their stds over
    trajectories (``std``), and the std of the seeds' means (``seed_std``, population)."""
    out = {}
    for key, first in summaries[0].items():
        if isinstance(first, dict) and "mean" in first:
            means = [s[key]["mean"] for s in summaries]
            out[key] = {
                "mean": sum(means) / len(summaries),
                "std": sum(s[key]["std"] for s in summaries) / len(summaries),
                "seed_std": _mean_std(means)["std"],
                "seeds": len(summaries),
            }
            if "rate" in first:
                out[key]["rate"] = out[key]["mean"]
        else:
            out[key] = first
    return out


def _over_seeds_table(rows: dict[str, dict]) -> str:
    """Held-out metrics as mean ± std over the seeds' means (rates in %)."""
    columns = (*TABLE2_COLUMNS, "sharp_turn", "goal_error", "success")
    lines = [
        "| | seeds | " + " | ".join(METRICS[c].label for c in columns) + " |",
        "|:--|--:|" + "--:|" * len(columns),
    ]
    for name, summary in rows.items():
        cells = []
        for c in columns:
            v, info = summary.get(c), METRICS[c]
            if not v or "seed_std" not in v:
                cells.append("—")
            elif info.indicator:
                cells.append(f"{100 * v['mean']:.1f} ± {100 * v['seed_std']:.1f}%")
            else:
                cells.append(f"{v['mean']:.{info.decimals}f} ± {v['seed_std']:.{info.decimals}f}")
        seeds = next((v["seeds"] for v in summary.values() if isinstance(v, dict) and "seeds" in v), "—")
        lines.append(f"| {name} | {seeds} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def reproduce(
    config: ReproduceConfig, out: str | Path, progress: bool = True, write_config: bool = True
) -> dict:
    """Run the whole pipeline into ``out``; returns the results written to ``out/results.json``.

    Stages already done in ``out`` (by an interrupted call with the same config) are resumed.
    ``write_config=False``: leave ``out/config.json`` to the caller (``kinlearn reproduce`` keeps its
    run record there). The planners' :class:`~kinlearn.errors.DomainWarning` about the held-out pairs
    (drawn apart from the training pairs, so some lie outside their range) is part of the experiment, not
    a fault its user can mend: it is not printed (the workers record theirs as ``domain_notes``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DomainWarning)
        return _reproduce(config, out, progress, write_config)


def _reproduce(config: ReproduceConfig, out: str | Path, progress: bool, write_config: bool) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    robot = load_robot(config.robot)
    if write_config:
        write_json(out / "config.json", asdict(config))
    timings: dict[str, float] = {}
    t_all = time.perf_counter()

    # 1. motor babbling and the learned FM/IM
    t0 = time.perf_counter()
    data = babble(
        BabblingConfig(
            robot=robot.name, walkers=1000, steps=max(1, config.transitions // 1000), seed=config.seed
        )
    )
    models = out / "models"
    fm_over = {} if config.model_epochs is None else {"epochs": config.model_epochs}
    fm_res = train_fm(
        data,
        fm_config(robot.name, config.model_preset),
        train_config("fm", config.model_preset, progress=progress, seed=config.seed, **fm_over),
        run_dir=models / "fm",
        resume=True,
    )
    im_res = train_im(
        data,
        im_config(robot.name, config.model_preset),
        train_config("im", config.model_preset, progress=progress, seed=config.seed, **fm_over),
        run_dir=models / "im",
        resume=True,
    )
    if config.distal_epochs > 0:
        im_res = train_im_distal(
            data,
            im_res.model,
            fm_res.model,
            train_config(
                "im", config.model_preset, progress=progress, seed=config.seed, epochs=config.distal_epochs
            ),
            run_dir=models / "im-through-fm",
            resume=True,
        )
    shutil.copyfile(models / "fm" / "fm.pt", models / "fm.pt")
    shutil.copyfile(im_res.checkpoint, models / "im.pt")
    validation = validate_models(fm_res.model, im_res.model, robot, seed=config.seed + 1)
    timings["babble + FM/IM"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    chains = _identify_chains(config, robot, data, models) if config.identify_samples else {}
    timings["identify chains"] = time.perf_counter() - t0

    # 2. endpoint pairs: training and held-out sets are disjoint draws of one generator
    pairs = make_endpoints(
        EndpointConfig(robot=robot.name, n=config.train_pairs + config.heldout_pairs, seed=config.seed)
    )
    train, heldout = pairs.split(config.train_pairs)
    save_endpoints(train, out / "endpoints_train.npz")
    save_endpoints(heldout, out / "endpoints_heldout.npz")

    # 3. the TM jobs: Table 1 sweep × seeds, kinlearn's default, the ablation, reference parity
    common = {
        "robot": robot.name,
        "models_dir": str(models.resolve()),
        "epochs": config.tm_epochs,
        "batch_size": config.tm_batch_size,
    }
    data = {"train": str(out / "endpoints_train.npz"), "heldout": str(out / "endpoints_heldout.npz")}
    heavy, light = [], []  # the pool takes the long jobs first, so that the workers finish together

    def add(name: str, cfg: TMTrainConfig, limit: int | None = None) -> None:
        job = {"kind": "tm", "name": name, "config": cfg.to_dict(), "run_dir": str(out / "tm" / name), **data}
        (heavy if cfg.fm == "learned" else light).append({**job, "limit": limit})

    for k, row in OPTIMIZER_SWEEP.items():
        names = [f"table1-{k}-seed{seed}" for seed in config.seeds]
        cfg = tm_preset("paper", loss=config.sweep_loss, seed=0, optim=_optim(row["optim"]), **common)
        job = {"kind": "seeds", "name": f"table1-{k}", "config": cfg.to_dict(), "seeds": list(config.seeds)}
        # SGD at the paper's rates diverges within steps (Table 1 #5–6): nothing to wait for
        (light if row["optim"]["name"] == "sgd" else heavy).append(
            {**job, "names": names, "run_dirs": [str(out / "tm" / n) for n in names], **data}
        )
    for fm in ("learned", "analytic"):
        for im in ("learned", "analytic"):
            add(f"ablation-fm_{fm}-im_{im}", tm_preset("default", fm=fm, im=im, seed=config.seed, **common))
    add(
        "reference-parity",
        tm_preset(
            "reference-parity",
            seed=config.seed,
            **{**common, "epochs": config.parity_epochs, "batch_size": 1},
        ),
        limit=config.parity_pairs,
    )
    if config.workspace_iterations:
        for kind in ("learned", "analytic"):
            cfg = _workspace_config(config, robot, models, kind)
            job = {"kind": "path", "name": f"workspace-{kind}", "config": cfg.to_dict()}
            (heavy if kind == "learned" else light).append(
                {**job, "run_dir": str(out / "workspace" / f"tm-fm_{kind}")}
            )
    jobs = heavy + light
    t0 = time.perf_counter()
    results = {r["name"]: r for r in run_jobs(_job, jobs, config.workers, config.backend, progress)}
    timings["training jobs"] = time.perf_counter() - t0

    # 4. the registry's free-space baselines on the same held-out pairs (the searches on the first 500)
    t0 = time.perf_counter()
    free = registry.names(avoids_obstacles=False)
    baselines = {
        registry.get(name).label: evaluate_plans(
            registry.make(name, robot).plan(Problem.make(robot, heldout.start, heldout.goal)), robot
        )
        for name in free
        if not registry.get(name).one_at_a_time
    }
    imitation = train_imitation(
        train, epochs=config.tm_epochs, batch_size=config.tm_batch_size, seed=config.seed, progress=progress
    )
    learned = Planner.load(out / "tm" / "ablation-fm_learned-im_learned")
    imitator = Planner(robot, imitation, learned.fm, learned.im)
    baselines["imitation TM (supervised, learned FM/IM)"] = evaluate_plans(
        imitator.plan(heldout.start, heldout.goal), robot
    )
    for name in (name for name in free if registry.get(name).one_at_a_time):
        n, label = min(len(heldout), 500), registry.get(name).label
        try:
            planner = registry.make(name, robot, seed=config.seed)
            plan = planner.plan(Problem.make(robot, heldout.start[:n], heldout.goal[:n]))
            baselines[registry.subset_label(label, n)] = evaluate_plans(plan, robot)
        except MissingDependencyError as exc:
            baselines[label] = {"skipped": str(exc)}
    timings["baselines"] = time.perf_counter() - t0

    # 5. the workspace task
    t0 = time.perf_counter()
    workspace = _workspace(config, robot, models, out / "workspace") if config.workspace_iterations else {}
    timings["workspace"] = time.perf_counter() - t0

    # 5b. the FM × IM ablation on position goals and on the paper's task
    t0 = time.perf_counter()
    fm_im = _fm_im(config, robot, models, chains, heldout, learned.tm) if chains else {}
    timings["FM × IM ablation"] = time.perf_counter() - t0

    # 6. tables, figures, results
    table1 = {}
    for k, row in OPTIMIZER_SWEEP.items():
        runs = [results[f"table1-{k}-seed{s}"] for s in config.seeds]
        ok = [r for r in runs if "diverged" not in r]
        table1[k] = {
            "optimizer": row["optim"],
            "paper_l_tm": row["paper_l_tm"],
            "seeds": len(runs),
            "diverged": len(runs) - len(ok),
            "final_l_tm": _mean_std([r["final_l_tm"] for r in ok]) if ok else None,
            "heldout": _merge([r["heldout"] for r in ok]) if ok else None,
            "per_seed": {r["seed"]: r["heldout"] for r in ok if "seed" in r},
            "train_seconds": _mean_std([r["train_seconds"] for r in runs]),
        }
    converged = [k for k in table1 if table1[k]["final_l_tm"] is not None]
    best = min(converged, key=lambda k: table1[k]["final_l_tm"]["mean"]) if converged else None
    ablation = {n: results[n] for n in results if n.startswith("ablation")}
    figures = _figures(out, robot, heldout)
    timings["total"] = time.perf_counter() - t_all
    res = {
        "config": asdict(config),
        "validation": validation,
        "table1": table1,
        "best_table1": best,
        "ablation": ablation,
        "reference_parity": results["reference-parity"],
        "baselines": baselines,
        "workspace": workspace,
        "fm_im": fm_im,
        "figures": figures,
        "timings_s": timings,
    }
    write_json(out / "results.json", res)
    (out / "results.md").write_text(_markdown(res))
    return res


def _identify_chains(config: ReproduceConfig, robot, data, models: Path) -> dict:
    """A chain identified without a URDF from the babbled states (their end effectors observed with 1 mm
    noise, the first ``identify_samples``), and the same chain with a residual MLP, saved in ``models``."""
    from ..data.recorded import Observations
    from ..models.forward_inverse import save_model
    from ..training.identify import IdentifyConfig, fit_residual, identify

    obs = Observations.from_transitions(data)
    n = min(config.identify_samples, len(obs))
    gen = torch.Generator().manual_seed(config.seed + 11)
    ef = obs.ef[:n] + 1e-3 * torch.randn(obs.ef[:n].shape, generator=gen, dtype=torch.float64)
    cfg = IdentifyConfig(seed=config.seed, mlp_steps=config.identify_mlp_steps)
    chain = identify((obs.theta[:n], ef), robot=robot, prior=False, config=cfg).model
    save_model(chain, models / "chain.pt")
    with_residual = copy.deepcopy(chain)
    residual_cfg = IdentifyConfig(residual=(64, 64), residual_steps=max(50, config.identify_mlp_steps))
    fit_residual(with_residual, obs.theta[:n], ef, residual_cfg, gen)
    save_model(with_residual, models / "chain_residual.pt")
    return {"chain": chain, "chain + residual": with_residual}


def _fm_im(config: ReproduceConfig, robot, models: Path, chains: dict, task, waypoint_tm) -> dict:
    """The FM × IM ablation (:func:`kinlearn.evaluation.fm_im.fm_im_ablation`)."""
    from ..models.forward_inverse import AnalyticFM, load_fm, load_im
    from .fm_im import fm_im_ablation
    from .workspace import heldout_pairs

    fms = {
        f"MLP FM ({config.model_preset} preset)": load_fm(models / "fm.pt", robot=robot.name),
        "chain (identified, no URDF)": chains["chain"],
        "chain + residual MLP": chains["chain + residual"],
        "analytic FK": AnalyticFM(robot),
    }
    pairs = heldout_pairs(robot, max(config.workspace_pairs, 1))
    mlp_im = load_im(models / "im.pt", robot=robot.name)
    return fm_im_ablation(robot, fms, mlp_im, pairs, task_pairs=task, waypoint_tm=waypoint_tm)


def _workspace_config(config: ReproduceConfig, robot, models: Path, kind: str):
    """The joint-path TM training of the workspace task, through the learned or the analytic FM (its
    rolled-out paths step no further than the FM's babbling step bound)."""
    from ..models.forward_inverse import AnalyticFM, load_fm
    from ..training.joint_path import PathTrainConfig

    fm = load_fm(models / "fm.pt", robot=robot.name) if kind == "learned" else AnalyticFM(robot)
    return PathTrainConfig(
        robot=robot.name,
        fm=kind,
        fm_checkpoint=str((models / "fm.pt").resolve()) if kind == "learned" else None,
        iterations=config.workspace_iterations,
        max_step=fm.max_step,
        batch_size=config.workspace_batch_size,
        seed=config.seed,
    )


def _workspace(config: ReproduceConfig, robot, models: Path, out: Path) -> dict:
    """The joint-path TMs (trained by the jobs) judged on held-out workspace pairs."""
    from ..models.forward_inverse import AnalyticFM, AnalyticIM, load_fm, load_im
    from ..models.joint_path import load_path_model
    from .workspace import evaluate_workspace, heldout_pairs

    fm, im = load_fm(models / "fm.pt", robot=robot.name), load_im(models / "im.pt", robot=robot.name)
    afm, aim = AnalyticFM(robot), AnalyticIM(robot)
    tms = {
        kind: load_path_model(out / f"tm-fm_{kind}" / "tm.pt", robot=robot.name)
        for kind in ("learned", "analytic")
    }
    pairs = heldout_pairs(robot, n=config.workspace_pairs)
    rows = {
        "kinlearn joint-path TM, trained through the learned FM": Planner(robot, tms["learned"]),
        "kinlearn joint-path TM, trained through the analytic FM": Planner(robot, tms["analytic"]),
    }
    free = registry.names(avoids_obstacles=False)
    searches = [name for name in free if registry.get(name).one_at_a_time]  # on the first 500 pairs
    rows.update({registry.get(n).label: registry.make(n, robot) for n in free if n not in searches})
    joint = evaluate_workspace(robot, pairs, rows)
    for name in searches:
        n_rrt, label = min(len(pairs), 500), registry.get(name).label
        sub = pairs.split(n_rrt)[0]
        try:
            row = evaluate_workspace(robot, sub, {"row": registry.make(name, robot, seed=config.seed)})["row"]
            joint[registry.subset_label(label, n_rrt)] = row
        except MissingDependencyError as exc:
            joint[label] = {"skipped": str(exc)}
    position = {}
    for fm_kind, f in (("learned", fm), ("analytic", afm)):
        for im_kind, i in (("learned", im), ("analytic", aim)):
            planner = Planner(robot, tms["learned"], f, i)
            name = f"kinlearn, goal joints from the {fm_kind} FM + {im_kind} IM"
            position[name] = evaluate_workspace(robot, pairs, {name: planner}, goal_kind="position")[name]
    paper = make_endpoints(EndpointConfig(robot=robot.name, n=config.heldout_pairs, seed=config.seed + 777))
    paper_task = evaluate_workspace(
        robot, paper, {"kinlearn joint-path TM (learned FM)": Planner(robot, tms["learned"])}
    )
    return {"pairs": len(pairs), "joint_goals": joint, "position_goals": position, "paper_task": paper_task}


def _optim(d: dict):
    from ..training.loop import OptimConfig

    return OptimConfig(**d)


def _figures(out: Path, robot, heldout) -> list[str]:
    try:
        from .plots import plot_good_bad, plot_histograms
    except ImportError:
        return []
    try:
        planner = Planner.load(out / "tm" / "ablation-fm_learned-im_learned")
        plan = planner.plan(heldout.start, heldout.goal)
        from .metrics import plan_metrics

        per = plan_metrics(plan, robot)
        paths = [
            plot_good_bad(plan, robot, out / "fig3_trajectories.png"),
            plot_histograms(per, out / "fig4_histograms.png"),
        ]
    except MissingDependencyError:
        return []
    return [str(Path(p).name) for p in paths]


def _markdown(res: dict) -> str:
    cfg = res["config"]
    lines = [
        f"# kinlearn reproduce — {cfg['robot']}",
        "",
        f"Held-out pairs: {cfg['heldout_pairs']}; training pairs: {cfg['train_pairs']}; TM epochs: "
        f"{cfg['tm_epochs']}; seeds: {len(cfg['seeds'])}; babbling transitions: {cfg['transitions']}; "
        f"FM/IM preset: {cfg['model_preset']}. Total wall time: {res['timings_s']['total']:.0f} s.",
        "",
        "## Learned FM/IM against the analytic robot",
        "",
        "```",
        json.dumps(res["validation"], indent=1, sort_keys=True, default=str),
        "```",
        "",
        "## Table 1 — final L_TM (paper Eq. 4, training set), mean ± std over seeds",
        "",
        "| # | optimiser | paper | kinlearn |",
        "|---|---|---|---|",
    ]
    for k, row in res["table1"].items():
        o = row["optimizer"]
        name = f"{o['name']}(lr={o['lr']:g})"
        ours = (
            "—"
            if row["final_l_tm"] is None
            else f"{row['final_l_tm']['mean']:.4f} ± {row['final_l_tm']['std']:.4f}"
        )
        if row["diverged"]:
            ours += f" ({row['diverged']} of {row['seeds']} seeds diverged)"
        lines.append(f"| {k} | {name} | {row['paper_l_tm']:.3f} | {ours} |")
    rows = {}
    for k, row in res["table1"].items():
        rows[f"paper #{k}"] = PAPER_TABLE2[k]
        if row["heldout"] is not None:
            rows[f"#{k} kinlearn, paper loss"] = row["heldout"]
    runs = {n.replace("ablation-", "default loss, "): r for n, r in res["ablation"].items()}
    runs["reference parity (authors' defects)"] = res["reference_parity"]
    rows.update({n: r["heldout"] for n, r in runs.items() if "heldout" in r})
    rows.update({k: v for k, v in res["baselines"].items() if "skipped" not in v})
    lines += [
        "",
        "## Table 2 — held-out trajectories (mean ± std over trajectories; a sweep row averages its seeds)",
        "",
        format_table(rows, columns=(*TABLE2_COLUMNS, "sharp_turn", "goal_error", "success")),
        "",
    ]
    over_seeds = {
        f"#{k} kinlearn, paper loss": row["heldout"]
        for k, row in res["table1"].items()
        if row["heldout"] is not None and len(cfg["seeds"]) > 1
    }
    if over_seeds:
        lines += [
            "## Table 2 over seeds — the held-out means of each seed, mean ± std over the seeds",
            "",
            _over_seeds_table(over_seeds),
        ]
    for k, v in res["baselines"].items():
        if "skipped" in v:
            lines.append(f"- {k}: skipped ({v['skipped']})")
    for n, r in runs.items():
        if "diverged" in r:
            lines.append(f"- {n}: {r['diverged']}")
    ws = res.get("workspace") or {}
    if ws:
        from .workspace import POSITION_COLUMNS, workspace_table

        lines += [
            "",
            f"## Workspace task — {ws['pairs']} held-out pairs uniform within ±90% of the joint range",
            "",
            "Goals given as joints (the goal state must be reached: end effector ≤ 1 cm and every joint ≤ 0.05 rad):",
            "",
            workspace_table({k: v for k, v in ws["joint_goals"].items() if "skipped" not in v}),
            "",
            "Goals given as an end-effector position (any configuration; success = end effector ≤ 1 cm). The "
            "goal joints come from the IM stepped through the FM along the straight line: the FM × IM ablation.",
            "",
            workspace_table(ws["position_goals"], POSITION_COLUMNS),
            "",
            "The same planner on held-out pairs of the paper's task:",
            "",
            workspace_table(ws["paper_task"]),
        ]
    if res.get("fm_im"):
        from .fm_im import fm_im_table

        lines += [
            "",
            "## FM × IM ablation",
            "",
            "Each cell: end-effector position goals on held-out workspace pairs, the goal joints' true end "
            "effector within 1 cm (median error) · the paper's task on its held-out pairs, planned by the "
            "waypoint TM through that FM and IM, executed within 1 cm (median). The chains are identified "
            "without a URDF from the same babbling, its end effectors observed with 1 mm noise.",
            "",
            fm_im_table(res["fm_im"]),
        ]
    if res["figures"]:
        lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in res["figures"]]
    return "\n".join(lines) + "\n"


def preset_config(name: str, **overrides) -> ReproduceConfig:
    if name not in REPRODUCE_PRESETS:
        raise ConfigError(f"unknown reproduce preset {name!r}; choose one of {', '.join(REPRODUCE_PRESETS)}")
    fields = {**REPRODUCE_PRESETS[name], **{k: v for k, v in overrides.items() if v is not None}}
    return dataclasses.replace(ReproduceConfig(), **fields)
