"""PPO on learned dynamics with the shipped policy's recipe: train on FIGNet's Push-v1, check on MuJoCo.

    python examples/ppo_push.py                       # the recipe of the shipped `push-ppo`, a
                                                      # quarter of its budget (resumable: re-run it)
    python examples/ppo_push.py --full                # the shipped policy's whole budget
    python examples/ppo_push.py --dynamics mujoco     # the same budget on MuJoCo, for comparison
    fignet-gym ppo-table runs/ppo_push_fignet runs/ppo_push_mujoco    # the transfer table
    python examples/ppo_push.py --full --ship my-push-ppo  # then ship it: load_policy("my-push-ppo")

The recipe (network, learning rate, noise, observation, reward terms, evaluation) is read from the
shipped policy's ``config.json`` (``fignet_gym/pretrained/policies/push-ppo/``; its card
``push-ppo.md`` has the budget in CPU hours and the scores), so this example always trains what
was shipped; only the options below change. The N pushes of a batch run as one learned graph per
step; a run folder holds checkpoints (re-running resumes, a larger ``--steps`` extends),
TensorBoard logs (``tensorboard --logdir runs``), ``progress.csv``, ``eval.csv`` (success and
return on both dynamics during training) and ``final_eval.json``. ``--ship NAME`` runs
``fignet-gym ppo-ship`` on the finished run (into ``--ship-dest``, default: the package's shipped
policies). The work is done by ``fignet_gym.agents.ppo.run.run_ppo`` (what ``fignet-gym ppo`` runs).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path

from fignet_gym.agents.ppo import RunConfig, run_ppo, transfer_table
from fignet_gym.agents.ppo.ship import ship_policy
from fignet_gym.agents.ppo.shipped import policies_dir

#: The shipped policy whose recipe this example trains.
SHIPPED = "push-ppo"
RECIPE = RunConfig.from_json(json.loads((policies_dir() / SHIPPED / "config.json").read_text()))
#: The default budget: a quarter of the shipped policy's, in whole PPO iterations.
ITERATION = RECIPE.ppo.num_envs * RECIPE.ppo.n_steps
SMALL_STEPS = max(ITERATION, RECIPE.ppo.total_timesteps // 4 // ITERATION * ITERATION)


@dataclass(frozen=True)
class Args:
    env: str = RECIPE.env_id
    dynamics: str = RECIPE.dynamics  # training dynamics: "fignet" or "mujoco"; evaluation runs on both
    steps: int = SMALL_STEPS  # environment steps in total
    full: bool = False  # train the shipped policy's whole budget instead of --steps
    num_envs: int = RECIPE.ppo.num_envs  # sub-environments stepped as one batched call
    n_steps: int = RECIPE.ppo.n_steps  # steps per sub-environment between PPO updates
    seed: int = RECIPE.ppo.seed
    eval_every: int = RECIPE.eval_every
    final_episodes: int = RECIPE.final_episodes  # episodes per dynamics of the final evaluation
    out: str = ""  # run folder (default: runs/ppo_push_<dynamics>)
    ship: str = ""  # after training, ship the run under this name (fignet-gym ppo-ship)
    ship_dest: str = ""  # folder of the shipped policy (default: the package's policies)


def parse(argv: Sequence[str] | None = None) -> Args:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for f in fields(Args):
        name = f"--{f.name.replace('_', '-')}"
        if isinstance(f.default, bool):
            p.add_argument(name, action="store_true")
        else:
            p.add_argument(name, type=type(f.default), default=f.default)
    return Args(**vars(p.parse_args(argv)))


def config(args: Args) -> RunConfig:
    """The shipped recipe with this run's env, dynamics, budget, batch shape, seed and evaluation."""
    steps = RECIPE.ppo.total_timesteps if args.full else args.steps
    rollout = args.num_envs * args.n_steps
    return replace(
        RECIPE,
        env_id=args.env,
        dynamics=args.dynamics,
        ppo=replace(RECIPE.ppo, total_timesteps=steps, num_envs=args.num_envs, n_steps=args.n_steps,
                    batch_size=min(RECIPE.ppo.batch_size, rollout), seed=args.seed),
        eval_every=args.eval_every,
        eval_episodes=min(RECIPE.eval_episodes, args.final_episodes),
        final_episodes=args.final_episodes,
        checkpoint_every=max(rollout, RECIPE.checkpoint_every),
    )


def main(argv: Sequence[str] | None = None) -> None:
    args = parse(argv)
    out = args.out or f"runs/ppo_push_{args.dynamics}"
    cfg = config(args)
    print(f"recipe of the shipped {SHIPPED!r} ({RECIPE.ppo.total_timesteps:,} steps on {RECIPE.dynamics}); "
          f"this run: {cfg.ppo.total_timesteps:,} steps on {cfg.dynamics} -> {out}"
          + ("" if args.full else "; the full budget: --full"))
    run_ppo(out, cfg, resume=Path(out, "config.json").exists())  # a stopped run continues
    print(transfer_table([out]))
    if args.ship:
        folder = ship_policy(out, args.ship, args.ship_dest or None, force=True)
        spec = str(folder) if args.ship_dest else args.ship
        print(f"shipped {folder}: fignet_gym.agents.load_policy({spec!r})")


if __name__ == "__main__":
    main()
