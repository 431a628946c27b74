"""Is an MPC run's planner or its model what limits it? Three checks of one finished `algo: mpc` run:

1. The model: its one-step error on the object's motion (and the hand's, `--hand`), on the
   run's own buffer (its local `checkpoint.pt`), binned by how far the object really moved, next
   to predicting no motion. A model that has not learnt contact is no better than "no motion"
   where the object moved.
2. The fit (`--refit UPDATES`): is it the data or the fit? Fresh models of the run's size fitted
   offline on 90 % of that buffer for UPDATES Adam steps, once with uniform batches (as the agent
   draws them) and once with `--oversample` of each batch drawn from transitions where the object
   moved >= `--moved-mm` (default 5: Meta-World push's observation noise, std 1 mm per number,
   alone makes a still puck "move" 2-3 mm between two observations), scored per bin on the other 10 % next to the run's own model; `--hidden` sizes
   the refits' layers (is it the model's capacity?), and `--nll-beta B ...` adds a uniform refit
   fitted by β-NLL for each B (is it the loss? agents/dynamics.py).
3. The planner: held-out success of the final model with the planner it trained with, and with
   a bigger one (200 candidates x 4 rounds x 15 steps, 20 elites: ~10x agents/mpc.yaml's search;
   `--no-bigger` skips it) and, where the run plans with a terminal value, without it (the
   predicted rewards alone: does the value steer the plans?) on the same goals and seeds (`--trials 0` skips it all); with `--refit`, also of each refitted
   model with the run's own planner (and its terminal value, if it has one): does a model that
   predicts contact better make the planner push?
4. The value (`--value-refit UPDATES`, a run with `terminal_value`): is it the value the run
   learnt online that steers its plans away? A fresh V fitted offline by TD(0) on the whole
   final buffer (as `TerminalValue.fit` fits it, UPDATES steps), and one that reads only the
   observation's entries `--value-inputs` (default: Meta-World's hand and object heights, the
   gripper and `object - tool, goal - object`: where the hand is relative to the puck and the
   puck to the goal, not where on the table), each planning with the run's model and search.
   `--value-heads K` adds a fit of K heads (`mpc.value_ensemble`), planning on their mean minus
   each `--value-pessimism` x their std (`mpc.value_pessimism`): does a pessimistic V keep the
   planner from exploiting states V overrates? `--heads-alone N` plans with each of the first N
   heads alone too (is the heads' mean better than one V because it averages them?). `--rows N`
   fits every value on the buffer's first N transitions (the data a refit at env step N saw;
   `--value-inputs` with no entries skips the second fit). `--value-from CHECKPOINT ...` plans
   with the terminal value saved in each of those checkpoints (another step of the same run) in
   place of the run's own, the model and search unchanged: is it the value or the model that
   changed between two checkpoints' plans (e.g. a refit's value against the one before it)?
   `--value-from-updates N` also goes on fitting each of them for N TD(0) steps on the first
   `--rows` transitions (a fresh Adam): what a refit fits, from those weights instead of new
   ones (is it the new weights or the fit to the newer data that changes the plans?).
   `--value-discount G ...` adds a refit (all inputs) at each discount G, the planner then
   discounting by G too (does a shorter-sighted V rank the states better?);
   `--no-value-all-inputs` skips the all-inputs refit where it is measured already.
5. TD-MPC's value (`--policy-value UPDATES`): is it V, the value of the data's behaviour, that
   misleads the planner, where the value of a policy that improves on it would not? Q and pi
   fitted offline by TD3+BC on the first `--rows` transitions, the planner scoring a plan's
   last state by `Q(s, pi(s))`, once alone and once with 5 of pi's rollouts through the model
   among each round's candidates (TD-MPC's policy-guided trajectories, `mpc.prior_trajectories`),
   after pi acting alone (no model, no search: what the planner adds to TD3+BC's policy).

    python benchmarks/mpc_probe.py benchmarks/runs/model_based/mpc-push-seed0 [--trials 10] [--object 4:7]
                                   [--refit 40000] [--oversample 0.5] [--hidden 256 256 256]
                                   [--nll-beta 0.5] [--no-bigger] [--value-refit 40000]
                                   [--value-inputs 2 3 6 39 40 41 42 43 44] [--value-heads 5]
                                   [--value-pessimism 0 1 2] [--heads-alone 2] [--rows 100000]
                                   [--value-discount 0.95 0.9] [--no-value-all-inputs] [--policy-value 40000]
                                   [--value-from <an earlier checkpoint.pt>] [--value-from-updates 40000] [--out NAME]

`--object`, `--hand`: where the object's and the hand's positions sit in the observation
(Meta-World: 4:7, 0:3).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from benchmarks.mpc_prior_probe import PriorOnly  # noqa: E402
from taskforge.agents.dynamics import DynamicsEnsemble  # noqa: E402
from taskforge.agents.policy_value import PolicyValue  # noqa: E402
from taskforge.agents.value import TerminalValue  # noqa: E402
from taskforge.rollouts import evaluate_rows  # noqa: E402
from taskforge.run import load_checkpoint, load_run  # noqa: E402

BIGGER = {"population": 200, "iterations": 4, "horizon": 15, "elites": 20}
PROPOSALS = 5  # pi's rollouts among each planning round's candidates (`mpc.prior_trajectories`; a tenth of the push preset's 50)
BINS_MM = ((0, 2), (2, 5), (5, 10), (10, 1000))
# Meta-World's observation: hand z, gripper, object z, then (tasks' `relative_positions`, last)
# object - tool and goal - object
RELATIVE_INPUTS = [2, 3, 6, 39, 40, 41, 42, 43, 44]


def distance_mm(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Row by row, the distance (mm) between two blocks of positions in metres."""
    return (a - b).norm(dim=1) * 1000


def mean_mm(mm: torch.Tensor) -> float | None:
    """The mean of a bin's distances; an empty bin has none."""
    return mm.mean().item() if len(mm) else None


def moved_mm(agent, obj: slice) -> torch.Tensor:
    """How far the object truly moved (mm) in each transition of the agent's buffer."""
    n = agent.buffer.size
    return distance_mm(agent.buffer.next_obs[:n, obj], agent.buffer.obs[:n, obj])


def object_motion_errors(agent, model: DynamicsEnsemble, obj: slice, rows: torch.Tensor, sample: int = 5000,
                         hand: slice | None = None) -> list[dict]:
    """Per bin of true object motion (mm), among the buffer's transitions `rows`: how many, the
    `model`'s mean error and the error of predicting no motion, on up to `sample` of the bin; with
    `hand`, the same two for the hand's position (a model that has not learnt the hand's own
    motion cannot plan where to take it)."""
    buffer, moved, members = agent.buffer, moved_mm(agent, obj), model.members
    result = []
    for lo, hi in BINS_MM:
        idx = rows[(moved[rows] >= lo) & (moved[rows] < hi)]
        pick = idx[:sample]
        with torch.no_grad():
            predicted, _ = model.mean_prediction(buffer.obs[pick][None].expand(members, -1, -1), buffer.actions[pick][None].expand(members, -1, -1))
        predicted = predicted.mean(0)
        row = {"moved_mm": [lo, hi], "transitions": len(idx), "model_error_mm": mean_mm(distance_mm(predicted[:, obj], buffer.next_obs[pick, obj])),
               "no_motion_error_mm": mean_mm(moved[pick])}
        if hand is not None:
            row |= {"hand_error_mm": mean_mm(distance_mm(predicted[:, hand], buffer.next_obs[pick, hand])),
                    "hand_no_motion_error_mm": mean_mm(distance_mm(buffer.next_obs[pick, hand], buffer.obs[pick, hand]))}
        result.append(row)
    return result


def refit(agent, train: torch.Tensor, moved: torch.Tensor, updates: int, oversample: float, seed: int,
          hidden: list[int] | None = None, threshold_mm: float = 5.0, nll_beta: float | None = None) -> DynamicsEnsemble:
    """A fresh model of the agent's size (or of `hidden` layers), fitted as `MPCAgent._fit` fits (standardised on the
    data, Adam, bootstrap batches per member) on the buffer rows `train` for `updates` steps;
    `oversample` of each batch drawn from the rows where the object moved >= `threshold_mm`;
    by β-NLL with `nll_beta` (default: the run's own loss)."""
    change = {"hidden_sizes": hidden or agent.mpc.hidden_sizes} | ({} if nll_beta is None else {"nll_beta": nll_beta})
    spec, generator = agent.mpc.model_copy(update=change), torch.Generator().manual_seed(seed)
    inputs, targets = agent.buffer.inputs_and_targets()
    model = DynamicsEnsemble(agent.buffer.obs.shape[1], agent.buffer.actions.shape[1], spec, generator)
    optimizer = torch.optim.Adam(model.parameters(), lr=spec.learning_rate, weight_decay=spec.weight_decay)
    model.fit_normalization(inputs[train], targets[train])
    movers = train[moved[train] >= threshold_mm]
    rare = round(spec.batch_size * oversample) if len(movers) else 0
    for _ in range(updates):
        idx = torch.cat([train[torch.randint(len(train), (spec.ensemble_size, spec.batch_size - rare), generator=generator)],
                         movers[torch.randint(max(len(movers), 1), (spec.ensemble_size, rare), generator=generator)]], dim=1)
        model.fit_batch(optimizer, inputs[idx], targets[idx])
    return model


def refit_value(agent, updates: int, seed: int, inputs: list[int] | None = None, rows: int | None = None,
                heads: int = 1, start: TerminalValue | None = None,
                discount: float | None = None) -> tuple[TerminalValue, dict[str, float]]:
    """A fresh terminal value of the run's size fitted as `MPCAgent._fit` fits it (TD(0) on the
    buffer, target network, the model's input statistics) for `updates` steps on the buffer's
    first `rows` transitions (default: all of them) at once, and its fit's metrics. With
    `inputs`, it reads only those observation entries: the others are standardised by an
    infinite spread, so every value they take reaches the network as 0. `heads`:
    `mpc.value_ensemble` (scored by their mean; set `pessimism` on the result for a lower bound).
    `start`: fit a copy of that value on from its weights instead (`heads` is then its own).
    `discount`: V's own discount instead of the run's (the planner then plans with it too)."""
    n, obs_size = rows or agent.buffer.size, agent.buffer.obs.shape[1]
    generator = torch.Generator().manual_seed(seed)
    value = copy.deepcopy(start) if start is not None else TerminalValue(
        obs_size, agent.mpc.hidden_sizes, discount or agent.mpc.discount, agent.mpc.value_tau, generator, heads)
    std = agent.model.in_std[:obs_size].clone()
    if inputs is not None:
        ignored = torch.ones(obs_size, dtype=torch.bool)
        ignored[inputs] = False
        std[ignored] = float("inf")
    optimizer = torch.optim.Adam(value.net.parameters(), lr=agent.mpc.learning_rate)
    metrics = value.fit(agent.buffer.obs[:n], agent.buffer.rewards[:n], agent.buffer.next_obs[:n], agent.model.in_mean[:obs_size],
                        std, optimizer, updates, agent.mpc.batch_size, generator)
    return value, metrics


def fit_policy_value(agent, updates: int, seed: int, rows: int | None = None) -> tuple[PolicyValue, dict[str, float]]:
    """TD-MPC's terminal value as `mpc.value_policy` fits it (TD3+BC, agents/policy_value.py),
    fresh, for `updates` steps on the buffer's first `rows` transitions at the run's discount,
    layer sizes and alpha: the value of a policy that improves on the data's while staying near
    it, fitted offline as `refit_value` fits V. Returns it and its fit's metrics."""
    n, obs_size, action_size = rows or agent.buffer.size, agent.buffer.obs.shape[1], agent.buffer.actions.shape[1]
    generator = torch.Generator().manual_seed(seed)
    mpc = agent.mpc
    value = PolicyValue(obs_size, action_size, mpc.hidden_sizes, mpc.discount, mpc.value_tau, generator, mpc.value_policy_alpha, mpc.value_bound)
    buffer = agent.buffer
    actions = agent.to_unit(buffer.actions[:n].to(agent.device)).cpu()  # the planner's units
    metrics = value.fit(buffer.obs[:n], actions, buffer.rewards[:n], buffer.next_obs[:n], agent.model.in_mean[:obs_size],
                        agent.model.in_std[:obs_size], value.optimizers(), updates, mpc.batch_size, generator)
    return value.requires_grad_(False), metrics


def saved_value(agent, path: Path) -> tuple[str, TerminalValue, dict]:
    """The terminal value saved in the checkpoint at `path` (the same run at another step), to
    plan with in place of the run's own: its label, the value (with its own input statistics)
    and where it came from."""
    if not path.is_file():
        sys.exit(f"error: {path}: --value-from expects a checkpoint.pt file (not found)")
    state = load_checkpoint(path)["agent"]
    if "value" not in state:
        sys.exit(f"error: {path}: --value-from: this checkpoint has no terminal value (mpc.terminal_value: false)")
    value = copy.deepcopy(agent.value)
    try:
        value.load_state_dict(state["value"])
    except RuntimeError:
        sys.exit(f"error: {path}: --value-from: its terminal value has another shape than this run's (mpc.value_ensemble or hidden_sizes differ)")
    step = state["global_step"]
    return f"value saved at step {step:,}", value, {"checkpoint": str(path), "step": step, "value_refits": state.get("value_refits", 0)}


def one_head(value: TerminalValue, head: int) -> TerminalValue:
    """Head `head` of a value of several, as a V of its own (a value refit of one head is one
    such draw: is what the heads' mean plans a lucky draw or their average?)."""
    alone = copy.deepcopy(value)
    for slow, fast in zip(alone.target, alone.net):
        for layer in (slow, fast):
            layer.weight, layer.bias = (torch.nn.Parameter(p[head : head + 1].detach().clone()) for p in (layer.weight, layer.bias))
    alone.heads = 1
    return alone


def motion_table(rows: list[dict]) -> None:
    print_table(["object moved (mm)", "transitions", "model error (mm)", "'no motion' error (mm)", "hand: model error", "hand: 'no motion'"],
                [[f"{r['moved_mm'][0]}-{r['moved_mm'][1]}", r["transitions"], r["model_error_mm"], r["no_motion_error_mm"],
                  r.get("hand_error_mm"), r.get("hand_no_motion_error_mm")] for r in rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--object", default="4:7", help="the object's position in the observation, start:stop")
    parser.add_argument("--hand", default="0:3", help="the hand's position in the observation, start:stop")
    parser.add_argument("--refit", type=int, default=0, help="Adam steps of the offline refits (0: skip them)")
    parser.add_argument("--oversample", type=float, default=0.5, help="share of each refit batch from transitions that moved the object (0: the uniform refit only)")
    parser.add_argument("--moved-mm", type=float, default=5.0, help="what counts as the object moving, for --oversample")
    parser.add_argument("--hidden", type=int, nargs="+", help="the refits' hidden layer sizes (default: the run's)")
    parser.add_argument("--nll-beta", type=float, nargs="+", default=[], help="also a uniform refit fitted by beta-NLL with each beta")
    parser.add_argument("--bigger", action=argparse.BooleanOptionalAction, default=True, help="also plan with a ~10x bigger search")
    parser.add_argument("--value-refit", type=int, default=0, help="TD(0) steps of two offline refits of the terminal value (0: skip them)")
    parser.add_argument("--value-inputs", type=int, nargs="*", default=RELATIVE_INPUTS, help="the observation entries the second value refit reads (none: skip it)")
    parser.add_argument("--value-all-inputs", action=argparse.BooleanOptionalAction, default=True,
                        help="fit the value refit that reads every input (--no-value-all-inputs: only the --value-inputs one, the other measured already)")
    parser.add_argument("--value-discount", type=float, nargs="+", default=[],
                        help="also a value refit (all inputs) with each of these discounts, planned with it (the run's: mpc.discount)")
    parser.add_argument("--policy-value", type=int, default=0,
                        help="also plan with TD-MPC's value, Q(s, pi(s)) of a policy fitted offline by TD3+BC for this many steps on --rows, "
                             "alone and with pi's rollouts proposed (0: skip it)")
    parser.add_argument("--value-heads", type=int, default=1, help="also a value refit of this many heads (1: none)")
    parser.add_argument("--value-pessimism", type=float, nargs="+", default=[0.0], help="plan with the heads' mean minus each of these x their std")
    parser.add_argument("--heads-alone", type=int, default=0, help="also plan with each of the first N of those heads alone")
    parser.add_argument("--rows", type=int, help="fit the values on the buffer's first ROWS transitions (default: all)")
    parser.add_argument("--value-from", type=Path, nargs="+", default=[], help="also plan with the terminal value saved in each of these checkpoints")
    parser.add_argument("--own", action=argparse.BooleanOptionalAction, default=True,
                        help="plan with the run's own value and with none (--no-own: only what else is asked, where those are measured already)")
    parser.add_argument("--value-from-updates", type=int, default=0, help="also with each of those values fitted on for this many TD(0) steps")
    parser.add_argument("--out", help="the result's name under benchmarks/results/ (default: mpc_probe_<run>[_<hidden>])")
    args = parser.parse_args()
    if args.value_from_updates and not args.value_from:  # it fits on the values --value-from loads: without them it would do nothing
        parser.error("--value-from-updates needs --value-from (the checkpoints whose values it fits on)")
    run = load_run(args.run)
    agent = run.agent
    if (args.value_refit or args.value_from or args.policy_value) and agent.value is None:
        sys.exit(f"error: {args.run}: --value-refit, --value-from and --policy-value need a run with mpc.terminal_value: true "
                 "(this one plans without a value)")
    obj, hand = (slice(*(int(x) for x in s.split(":"))) for s in (args.object, args.hand))
    agent.load_state_dict(load_checkpoint(args.run / "checkpoint.pt")["agent"])  # the buffer: the final policy file has none
    if args.rows is not None and not 0 < args.rows <= agent.buffer.size:
        sys.exit(f"error: {args.run}: --rows {args.rows} must be in 1..{agent.buffer.size} (the transitions its buffer holds)")
    everything = torch.arange(agent.buffer.size)
    motion = object_motion_errors(agent, agent.model, obj, everything, hand=hand)
    motion_table(motion)
    payload: dict = {"run": str(args.run), "step": agent.global_step, "object_motion": motion}
    refits: dict[str, DynamicsEnsemble] = {}
    if args.refit:
        split = torch.randperm(agent.buffer.size, generator=torch.Generator().manual_seed(0))
        held_out, train = split[: len(split) // 10], split[len(split) // 10 :]
        moved = moved_mm(agent, obj)
        fits = [("refit, uniform", 0.0, None)]
        fits += [(f"refit, {args.oversample:.0%} moves >= {args.moved_mm:g} mm", args.oversample, None)] if args.oversample else []
        fits += [(f"refit, uniform, beta-NLL {beta:g}", 0.0, beta) for beta in args.nll_beta]
        for label, share, beta in fits:
            start = time.perf_counter()
            refits[label] = refit(agent, train, moved, args.refit, share, seed=0, hidden=args.hidden, threshold_mm=args.moved_mm, nll_beta=beta)
            print(f"{label}: {args.refit} steps in {time.perf_counter() - start:.0f} s")
        models = {"run's model": agent.model} | refits
        payload["refit"] = {"updates": args.refit, "oversample": args.oversample, "moved_mm": args.moved_mm, "hidden": args.hidden or agent.mpc.hidden_sizes,
                            "nll_beta": args.nll_beta, "run_nll_beta": agent.mpc.nll_beta, "held_out": len(held_out),
                            "errors": {label: object_motion_errors(agent, model, obj, held_out, hand=hand) for label, model in models.items()}}
        for label, rows in payload["refit"]["errors"].items():
            print(f"\n{label}, held-out 10 %:")
            motion_table(rows)
    values: dict[str, TerminalValue] = {}
    if args.value_refit:
        fits, heads = {}, args.value_heads
        runs = [("value refit, all inputs", None, 1)] if args.value_all_inputs else []
        runs += [(f"value refit, inputs {' '.join(map(str, args.value_inputs))}", args.value_inputs, 1)] if args.value_inputs else []
        runs += [(f"value refit, {heads} heads", None, heads)] if heads > 1 else []
        runs = [(label, inputs, count, None) for label, inputs, count in runs]
        runs += [(f"value refit, all inputs, discount {gamma:g}", None, 1, gamma) for gamma in args.value_discount]
        for label, inputs, count, gamma in runs:
            start = time.perf_counter()
            value, fits[label] = refit_value(agent, args.value_refit, seed=0, inputs=inputs, rows=args.rows, heads=count, discount=gamma)
            print(f"{label}: {args.value_refit} steps in {time.perf_counter() - start:.0f} s, {fits[label]}")
            if count == 1:
                values[label] = value
                continue
            for kappa in args.value_pessimism:  # the same heads, scored by mean - kappa x std
                scored = copy.copy(value)
                scored.pessimism = kappa
                values[f"{label}, mean - {kappa:g} std"] = scored
            for head in range(min(args.heads_alone, count)):
                values[f"{label}: head {head} alone"] = one_head(value, head)
        payload["value_refit"] = {"updates": args.value_refit, "inputs": args.value_inputs, "rows": args.rows or agent.buffer.size,
                                  "heads": heads, "pessimism": args.value_pessimism, "discounts": args.value_discount, "fits": fits}
    for path in args.value_from:
        label, values[label], source = saved_value(agent, path)
        if args.value_from_updates:
            start = time.perf_counter()
            fitted, source["fit"] = refit_value(agent, args.value_from_updates, seed=0, rows=args.rows, start=values[label])
            values[f"{label}, + {args.value_from_updates} TD steps"] = fitted
            print(f"{label}: {args.value_from_updates} more steps in {time.perf_counter() - start:.0f} s, {source['fit']}")
        payload.setdefault("value_from", []).append(source)
    policies: dict[str, PolicyValue] = {}
    if args.policy_value:
        start = time.perf_counter()
        label = f"Q(s, pi(s)), TD3+BC {args.policy_value} steps"
        policies[label], fit = fit_policy_value(agent, args.policy_value, seed=0, rows=args.rows)
        print(f"{label}: in {time.perf_counter() - start:.0f} s, {fit}")
        payload["policy_value"] = {"updates": args.policy_value, "rows": args.rows or agent.buffer.size, "fit": fit,
                                   "proposals": PROPOSALS}
    if args.trials:
        payload |= {"trials": args.trials,
                    "planners": compare_planners(agent, run, args.trials, refits, args.bigger, values, args.own, policies)}
    name = args.out or f"mpc_probe_{args.run.name}" + (f"_{'x'.join(map(str, args.hidden))}" if args.hidden else "")
    print(f"wrote {write_result(name, payload)}")


def compare_planners(agent, run, trials: int, refits: dict[str, DynamicsEnsemble], bigger: bool = True,
                     values: dict[str, TerminalValue] | None = None, own: bool = True,
                     policies: dict[str, PolicyValue] | None = None) -> list[dict]:
    """Held-out success of the final model with its own planner (and with `BIGGER`, and without
    its terminal value where it has one; `own=False` skips these, measured already), of each of
    `refits` with the run's own planner, of the run's model and search with each of `values`
    in place of its own, and with each of `policies` (TD-MPC's `Q(s, pi(s))`; first its pi
    acting alone, no model and no search) alone and with
    `PROPOSALS` rollouts of its pi among each round's candidates (the search started from pi's
    own, as `mpc.prior_trajectories` does)."""
    task, task_file, stages = run.phases[-1]
    own_model, own_planner, own_value, own_prior = agent.model, agent.spec.planning, agent.value, agent.prior
    plans = [("run's model", own_model, "as trained", {}, own_value, None)] if own else []
    plans += [("run's model", own_model, "bigger search", BIGGER, own_value, None)] if bigger else []
    # is it the terminal value that steers the plans? the same model and search, scored by reward alone
    plans += [("run's model", own_model, "no terminal value", {}, None, None)] if own and own_value is not None else []
    plans += [(label, model, "as trained", {}, own_value, None) for label, model in refits.items()]
    # a value of another discount than the run's plans with its own (the horizon's rewards and V's weight)
    plans += [("run's model", own_model, label, {} if value.discount == own_planner.discount else {"discount": value.discount}, value, None)
              for label, value in (values or {}).items()]
    for label, value in (policies or {}).items():
        plans += [("no model", None, f"{label}: pi alone, no search", {}, value, value.policy),
                  ("run's model", own_model, label, {}, value, None),
                  ("run's model", own_model, f"{label}, {PROPOSALS} of pi's rollouts proposed", {"prior_trajectories": PROPOSALS}, value, value.policy)]
    rows = []
    for model_label, model, planner, change, value, prior in plans:
        agent.model, agent.mpc, agent.value = model, own_planner.model_copy(update=change), value
        agent.prior = own_prior if prior is None else prior
        # pi's own row: the policy acting alone on the same goals (does the search add to it?)
        player = PriorOnly(agent) if model is None else agent
        start = time.perf_counter()
        (result,) = evaluate_rows(player, task, task_file, [(stages[-1], None)], "test", trials, 1, seed=0, stop_on_success=True)
        rows.append({"model": model_label, "planner": planner, **agent.mpc.model_dump(include={"population", "iterations", "horizon", "elites", "discount"}),
                     "success_rate": result.as_dict()["success_rate"], "seconds": time.perf_counter() - start})
    agent.model, agent.mpc, agent.value, agent.prior = own_model, own_planner, own_value, own_prior
    print_table(["model", "planner", "population x rounds x horizon", "held-out success", "s"],
                [[r["model"], r["planner"], f"{r['population']} x {r['iterations']} x {r['horizon']}", f"{r['success_rate']:.2f}", r["seconds"]]
                 for r in rows])
    return rows


if __name__ == "__main__":
    main()
