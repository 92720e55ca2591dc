"""Tabular Q-learning on ConAg's Gymnasium env (`conag.env.ConAgGymEnv`), a few hundred steps.

The state is coarse: whether the agent holds a brick, and where the nearest brick it senses
lies relative to its heading (ahead, left, right, behind, or none in range). Five actions:
forward, turn left, turn right, grab, drop. The reward is the env's (sites filled) plus
0.5 for a grab, less 0.01 a step, through the env's configurable reward. Far too short to learn the task;
it shows the loop. `python3 examples/train_tabular.py --steps 300` (needs `pip install -e '.[env]'`).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from conag.env import ConAgGymEnv
from protocol.messages import ACTIONS, CHANNELS

MOVES = [(1.0, 0.0, "none"), (0.0, 0.4, "none"), (0.0, -0.4, "none"), (0.0, 0.0, "grab"), (0.0, 0.0, "drop")]
BRICK = CHANNELS.index("brick")


def state_of(obs: dict) -> tuple[int, int]:
    """(holding, where the nearest brick is: 0 ahead, 1 left, 2 behind, 3 right, 4 none in range)."""
    sectors = len(obs["ranges"]) // len(CHANNELS)
    bricks = obs["ranges"][BRICK * sectors:(BRICK + 1) * sectors]
    seen = np.flatnonzero(bricks >= 0)
    if not seen.size:
        return int(obs["holding"]), 4
    k = seen[np.argmin(bricks[seen])]
    off = ((k + 0.5) * 2 * math.pi / sectors - float(obs["heading"][0]) + math.pi) % (2 * math.pi) - math.pi
    return int(obs["holding"]), int(((off + math.pi / 4) % (2 * math.pi)) // (math.pi / 2))


def grab_bonus(env, agent: str, filled_now: int) -> float:
    """Sites filled during the step, plus 0.5 when the agent's grab took a brick, less 0.01 a step."""
    return filled_now + (0.5 if env.frames[agent].grabbed else 0.0) - 0.01


def train(steps: int = 300, seed: int = 0, scenario: str = "scenarios/quick_wall.toml") -> dict:
    """Q-learning for `steps` env steps; returns the table, the return and the env steps per second."""
    rng = np.random.default_rng(seed)
    q = np.zeros((2, 5, len(MOVES)))
    env = ConAgGymEnv(scenario, reward=grab_bonus, max_cycles=steps)
    try:
        obs, _ = env.reset(seed=seed)
        s, total, start, done = state_of(obs), 0.0, time.perf_counter(), 0
        for done in range(1, steps + 1):  # noqa: B007 -- the count is returned
            a = int(rng.integers(len(MOVES))) if rng.random() < 0.2 else int(np.argmax(q[s]))
            speed, turn, action = MOVES[a]
            obs, reward, terminated, truncated, _ = env.step(
                {"speed": [speed], "turn": [turn], "action": ACTIONS.index(action)})
            s2 = state_of(obs)
            q[s][a] += 0.5 * (reward + 0.9 * q[s2].max() * (not terminated) - q[s][a])
            s, total = s2, total + reward
            if terminated or truncated:
                break
        return {"q": q, "return": total, "steps": done, "steps_per_second": done / (time.perf_counter() - start)}
    finally:
        env.close()


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    result = train(args.steps, args.seed)
    print(f"{result['steps']} steps, return {result['return']:.2f}, "
          f"{result['steps_per_second']:.0f} env steps per second")
