"""Train one TM configuration for several seeds at once, in lockstep.

A seed sweep (the paper's Table 1 over ten seeds) trains small TMs at batch 64 through small frozen
FM/IM: each step is hundreds of tiny operations, and the time goes to their overhead, not to
arithmetic. Here the seeds' TMs run as one batched model: their GRUs step together as batched
matrix products, and every FM/IM call of the rectification takes all seeds' samples at once. Each
seed keeps everything of its own: its initial weights and its pair order (both drawn from its seed,
as :func:`kinlearn.training.tm.train_tm` draws them), its loss and its optimiser state (the optimisers
are elementwise, so one optimiser over all seeds' parameters updates each seed as its own would).
The result is each seed's run as :func:`~kinlearn.training.tm.train_tm` would have written it, up to
float rounding: ``run_dir/tm.pt`` (resumable by either function), ``metrics.jsonl``,
``config.json``. A seed that diverges stops alone (its reason in ``diverged.json``); the others go on.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path

import torch
from tqdm.auto import tqdm

from ..data.endpoints import EndpointPairs
from ..errors import CheckpointError, ConfigError, TrainingDivergedError
from ..io import content_sha256, remove_stale_tmp, write_json
from ..models.rollout import rectify, tm_loss
from ..models.trajectory import TMConfig, TrajectoryModel
from .loop import (
    RunLogger,
    _check_divergence,
    _config_differences,
    _stored_step,
    _training_state,
    _truncate_log,
    make_optimizer,
    make_schedule,
    seed_everything,
)
from .tm import (
    WAYPOINT_BOUND_REACHES,
    TMTrainConfig,
    _checked_robot,
    _learned_dependencies,
    _load_run,
    _save_run_checkpoint,
    _train_config_dict,
    _training_record,
    arm_reach,
    build_fm_im,
)

__all__ = ["stacked_forward", "train_tm_seeds"]


def stacked_forward(members: Sequence[TrajectoryModel], s0: torch.Tensor, sT: torch.Tensor) -> torch.Tensor:
    """Waypoints of ``M`` one-layer TMs, each on its own batch: ``s0``, ``sT`` ``(M, B, S)`` →
    ``(M, B, T - 1, 3)``; the same numbers as ``members[m](s0[m], sT[m])``, up to rounding, and
    differentiable with respect to every member's parameters."""
    first = members[0].config
    _check_lockstep(first)
    M, B = s0.shape[:2]
    H, steps = first.gru_hidden, first.steps - 1

    def stack(name: str) -> torch.Tensor:
        return torch.stack([m.get_parameter(name) for m in members])

    buf = {
        k: torch.stack([m.get_buffer(k) for m in members])
        for k in ("in_mean", "in_std", "out_mean", "out_std")
    }
    x = (torch.cat((s0, sT), dim=-1) - buf["in_mean"][:, None]) / buf["in_std"][:, None]
    w_ih, w_hh = stack("gru.weight_ih_l0"), stack("gru.weight_hh_l0")
    gi = torch.baddbmm(stack("gru.bias_ih_l0")[:, None], x.to(w_ih.dtype), w_ih.transpose(1, 2))
    gi_r, gi_z, gi_n = gi.chunk(3, dim=-1)
    b_hh = stack("gru.bias_hh_l0")[:, None]
    h = stack("h0")[:, 0].expand(M, B, H) if first.h0 == "learned" else gi.new_zeros(M, B, H)
    outs = []
    for _ in range(steps):  # nn.GRU's equations, gate order r, z, n
        gh_r, gh_z, gh_n = torch.baddbmm(b_hh, h, w_hh.transpose(1, 2)).chunk(3, dim=-1)
        r, z = torch.sigmoid(gi_r + gh_r), torch.sigmoid(gi_z + gh_z)
        n = torch.tanh(gi_n + r * gh_n)
        h = n + z * (h - n)
        outs.append(h)
    out = torch.stack(outs, dim=2).reshape(M, B * steps, H)
    hid = torch.tanh(
        torch.baddbmm(stack("shared.0.bias")[:, None], out, stack("shared.0.weight").transpose(1, 2))
    )
    hid = torch.tanh(
        torch.baddbmm(stack("head.0.bias")[:, None], hid, stack("head.0.weight").transpose(1, 2))
    )
    ef = torch.baddbmm(stack("head.2.bias")[:, None], hid, stack("head.2.weight").transpose(1, 2))
    ef = ef * buf["out_std"][:, None] + buf["out_mean"][:, None]
    return ef.reshape(M, B, steps, 3)


def _check_lockstep(tm: TMConfig) -> None:
    if tm.gru_layers != 1 or tm.h0 == "random":
        raise ConfigError("seeds train in lockstep only for one-layer TMs with a zeros or learned h0")


def _member_optimizer_state(full: dict, member: int, n_params: int) -> dict:
    """The state dict an optimiser over one member's parameters alone would have."""
    state = full["state"]
    return {
        "state": {j: state[member * n_params + j] for j in range(n_params) if member * n_params + j in state},
        "param_groups": [{**g, "params": list(range(n_params))} for g in full["param_groups"]],
    }


def _joined_optimizer_state(members: list[dict], n_params: int) -> dict:
    """The inverse of :func:`_member_optimizer_state` over all members."""
    state = {}
    for i, m in enumerate(members):
        state.update({i * n_params + int(j): v for j, v in m["state"].items()})
    groups = [{**g, "params": list(range(len(members) * n_params))} for g in members[0]["param_groups"]]
    return {"state": state, "param_groups": groups}


def train_tm_seeds(
    config: TMTrainConfig,
    seeds: Sequence[int],
    run_dirs: Sequence[str | Path],
    train: EndpointPairs,
    *,
    resume: bool = True,
    progress: bool = True,
) -> dict[int, TrajectoryModel | TrainingDivergedError]:
    """Train ``config`` once per seed (``config.seed`` is replaced by each), seed ``seeds[i]`` into
    ``run_dirs[i]``; returns each seed's trained TM, or the :class:`TrainingDivergedError` that
    stopped it. Resumes from the run folders' ``tm.pt`` (all at one epoch) when ``resume``.

    Needs a one-layer TM whose ``h0`` is not random and every parameter trainable (the Table 1
    sweep's and the default preset's); other configurations raise :class:`ConfigError`.
    """
    seeds = [int(s) for s in seeds]
    run_dirs = [Path(d) for d in run_dirs]
    if not seeds or len(seeds) != len(run_dirs) or len(set(seeds)) != len(seeds):
        raise ConfigError("give one run folder per seed, and each seed once")
    if config.trainable != "all":
        raise ConfigError("seeds train in lockstep only with every parameter trainable (trainable='all')")
    _check_lockstep(config.tm)
    robot = _checked_robot(config, train)
    configs = [dataclasses.replace(config, seed=s) for s in seeds]
    records = [_training_record(c) for c in configs]  # as each run's checkpoint records its training
    fm, im = build_fm_im(config)
    depends = _learned_dependencies(config)
    for m in (fm, im):
        m.validate_inputs = False  # a diverging TM is caught by the checks below

    members, gens = [], []
    for cfg in configs:  # each seed's initial weights and pair order, drawn as train_tm draws them
        gens.append(seed_everything(cfg.seed))
        tm = TrajectoryModel(cfg.tm)
        tm.fit_normalization(train.start, train.goal)
        members.append(tm)
    n_params = len(list(members[0].parameters()))
    opt = make_optimizer(config.optim, [p for m in members for p in m.parameters()])
    n, M = len(train), len(members)
    total = config.epochs * math.ceil(n / config.batch_size)
    sched = make_schedule(opt, config.schedule, total)
    data_sha256 = content_sha256((train.start, train.goal))
    bound = WAYPOINT_BOUND_REACHES * arm_reach(robot)

    start_epoch, loss_ref, histories = 0, [None] * M, [[] for _ in range(M)]
    dead: dict[int, TrainingDivergedError] = {}
    for i, d in enumerate(run_dirs):
        remove_stale_tmp(d, "tm.pt")
        if resume and (d / "diverged.json").exists():
            dead[i] = TrainingDivergedError(json.loads((d / "diverged.json").read_text())["reason"])
    live_ckpts = [i for i in range(len(seeds)) if i not in dead and (run_dirs[i] / "tm.pt").exists()]
    if resume and live_ckpts:
        payloads = {i: _load_run(run_dirs[i] / "tm.pt", robot.name, depends, data_sha256) for i in live_ckpts}
        epochs = set()
        for i, p in payloads.items():
            epochs.add(_stored_step(run_dirs[i] / "tm.pt", p["extra"]))
            diffs = _config_differences(p["extra"].get("train_config", {}), records[i])
            if diffs:
                raise CheckpointError(
                    f"{run_dirs[i] / 'tm.pt'} was trained with another configuration ({'; '.join(diffs)})"
                )
        if len(epochs) != 1 or len(payloads) != len(seeds) - len(dead):
            raise CheckpointError(
                "the seeds' runs stopped at different epochs; resume them one by one with train_tm"
            )
        empty = {"state": {}, "param_groups": payloads[live_ckpts[0]]["extra"]["optimizer"]["param_groups"]}
        for i, p in payloads.items():
            members[i].load_state_dict(p["state_dict"])
            gens[i].set_state(p["extra"]["generator"])
            loss_ref[i] = p["extra"].get("loss_ref")
            histories[i] = list(p["extra"].get("history", []))
        states = [payloads[i]["extra"]["optimizer"] if i in payloads else empty for i in range(len(seeds))]
        opt.load_state_dict(_joined_optimizer_state(states, n_params))
        sched.load_state_dict(payloads[live_ckpts[0]]["extra"]["scheduler"])
        start_epoch = epochs.pop()
    for d, cfg in zip(run_dirs, configs, strict=True):
        d.mkdir(parents=True, exist_ok=True)
        _truncate_log(d / "metrics.jsonl", start_epoch)
        write_json(d / "config.json", _train_config_dict(cfg))

    per_member_loss = torch.func.vmap(
        lambda wp, rect, s0, sT: tm_loss(wp, rect, s0, sT, members[0].layout, config.loss)
    )
    loggers, t0 = [RunLogger(d) for d in run_dirs], time.perf_counter()
    try:
        bar = tqdm(
            range(start_epoch, config.epochs),
            desc=f"train {M} TMs",
            disable=not progress,
            initial=start_epoch,
            total=config.epochs,
        )
        for epoch in bar:
            if len(dead) == M:
                break
            for m in members:
                m.train()
            perms = torch.stack([torch.randperm(n, generator=g) for g in gens])
            sums = [dict() for _ in range(M)]
            for i in range(0, n, config.batch_size):
                run = [k for k in range(M) if k not in dead]  # a stopped seed costs nothing more
                idx = perms[run, i : i + config.batch_size]
                s0, sT = train.start[idx], train.goal[idx]
                R, B = idx.shape
                wp = stacked_forward([members[k] for k in run], s0, sT)
                flat = (wp.reshape(R * B, *wp.shape[2:]), s0.reshape(R * B, -1), sT.reshape(R * B, -1))
                if config.loss.gradient == "stop":
                    with torch.no_grad():
                        rect, _ = rectify(flat[0].detach(), flat[1], flat[2], fm, im, members[0].layout)
                else:
                    rect, _ = rectify(*flat, fm, im, members[0].layout)
                loss, terms = per_member_loss(wp, rect.reshape(R, B, *rect.shape[1:]), s0, sT)
                ok = (torch.isfinite(loss) & (wp.detach().abs().amax(dim=(1, 2, 3)) <= bound)).tolist()
                for j in [j for j in range(R) if not ok[j]]:
                    dead[run[j]] = TrainingDivergedError(
                        f"TM training diverged at epoch {epoch + 1} (loss {loss[j].item():.4g}, a waypoint "
                        f"beyond {bound:.3g} m = {WAYPOINT_BOUND_REACHES:g} × the arm's reach); lower the learning rate"
                    )
                keep = [j for j in range(R) if ok[j]]
                if not keep:
                    break
                for j in keep:
                    if loss_ref[run[j]] is None:
                        loss_ref[run[j]] = float(loss[j].detach())
                opt.zero_grad(set_to_none=True)
                loss[keep].sum().backward()
                for j in [
                    j for j in range(R) if not ok[j]
                ]:  # no gradient, no step: it stays where it stopped
                    for p in members[run[j]].parameters():
                        p.grad = None
                opt.step()
                sched.step()
                w = B / n
                vals = torch.stack([loss.detach(), *terms.values()], dim=1).tolist()
                for j in keep:
                    for name, v in zip(("loss", *terms), vals[j], strict=True):
                        sums[run[j]][name] = sums[run[j]].get(name, 0.0) + v * w
            state, where = opt.state_dict(), f"TM training diverged at epoch {epoch + 1}"
            for k in range(M):
                if k in dead:
                    continue
                try:
                    _check_divergence(sums[k]["loss"], loss_ref[k], where)
                except TrainingDivergedError as exc:
                    dead[k] = exc
                    continue
                record = {
                    "epoch": epoch + 1,
                    "lr": sched.get_last_lr()[0],
                    "seconds": time.perf_counter() - t0,
                }
                record.update({f"train/{name}": v for name, v in sums[k].items()})
                loggers[k].log(record)
                histories[k].append(record)
                member = (_member_optimizer_state(state, k, n_params), sched, gens[k], loss_ref[k])
                extra = _training_state(epoch + 1, "epoch", *member, records[k], histories[k])
                _save_run_checkpoint(
                    run_dirs[k] / "tm.pt", configs[k], members[k], extra, data_sha256, depends
                )
            for k, exc in dead.items():
                if not (run_dirs[k] / "diverged.json").exists():
                    write_json(run_dirs[k] / "diverged.json", {"reason": str(exc)})
            live = [k for k in range(M) if k not in dead]
            if live:
                bar.set_postfix(l_tm=f"{min(sums[k]['paper_l_tm'] for k in live):.3g}", live=len(live))
    finally:
        for lg in loggers:
            lg.close()
    for m in members:
        m.eval()
    return {s: dead.get(i, members[i]) for i, s in enumerate(seeds)}
