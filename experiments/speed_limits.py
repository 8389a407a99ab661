"""What the env contract leaves of the speed floors of ``ssme-envs bench``.

Two promises of the envs cost time no implementation can remove: an env gives the same bits
alone and in a batch (so the float step and the array step use one power function, whose
bits both carriers must reproduce: today numpy's SIMD ``np.power``), and the native vector env
equals gymnasium's ``SyncVectorEnv`` (so each sub-env draws its episodes from its own
generator: one generator call per restart). This script measures those costs beside
Pendulum-v1 and CartPole-v1's native vector env in the same run, and gives the best ratio each
env could reach were everything else in its step free, with today's power function and with
the C library's (``math.pow`` on floats, ``np.float_power`` on arrays: the same bits, measured
here too).

    python experiments/speed_limits.py [--rounds 5]

Writes experiments/results/speed_limits.md.
"""

from __future__ import annotations

import argparse
import math
import timeit
from pathlib import Path

import gymnasium as gym
import numpy as np

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs import bench
from ssme_envs.envs import catalogue
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_task import NozzleTask
from ssme_envs.models.nozzle import NozzleParameters, rk4_floats, rk4_parameters
from ssme_envs.outputs import write_text

RESULTS = Path(__file__).resolve().parent / "results" / "speed_limits.md"
N = 4096  # the vector size of the floors
# the floors of the envs with a hysteretic joint: single over Pendulum-v1, native
# vector (N = 4096) over CartPole-v1's
FLOORS = {
    "ssme_envs/NozzleTVC-v0": {"single": 0.8, "vector": 0.4},
    "ssme_envs/LauncherPitch-v0": {"single": 0.4, "vector": 0.2},
}


def _best(run, steps: int, rounds: int) -> float:
    """Best seconds per step of ``run(steps)`` over ``rounds``."""
    return min(run(steps) for _ in range(rounds)) / steps


def power_costs(exponent: float, rounds: int) -> dict[str, float]:
    """Seconds per power: on one Python float (numpy's SIMD loop, the C library's pow) and per
    element of an (N,) array (the same two); and the share of |w| in [0, 0.1) rad on which
    the C library's bits differ from numpy's (and from ``np.float_power``'s)."""
    power, pow_ = np.power, math.pow
    w = 0.0317
    per = 200_000
    scalar_simd = min(timeit.repeat(lambda: float(power(w, exponent)), number=per, repeat=rounds)) / per
    scalar_libm = min(timeit.repeat(lambda: pow_(w, exponent), number=per, repeat=rounds)) / per
    rng = np.random.default_rng(0)
    row, out = rng.uniform(0.0, 0.1, N), np.empty(N)
    reps = 2000
    vector_simd = min(timeit.repeat(lambda: power(row, exponent, out=out), number=reps, repeat=rounds))
    vector_libm = min(
        timeit.repeat(lambda: np.float_power(row, exponent, out=out), number=reps, repeat=rounds)
    )
    sample = rng.uniform(0.0, 0.1, 50_000)
    libm = np.array([pow_(v, exponent) for v in sample.tolist()])
    return {
        "scalar_simd": scalar_simd,
        "scalar_libm": scalar_libm,
        "vector_simd": vector_simd / reps / N,
        "vector_libm": vector_libm / reps / N,
        "differ_simd": float(np.mean(libm != np.power(sample, exponent))),
        "differ_float_power": float(np.mean(libm != np.float_power(sample, exponent))),
    }


def rk4_steps(env_id: str) -> tuple[int, float]:
    """RK4 steps of the joint per env step and their length (s)."""
    task = catalogue.spec(env_id).build_task()
    if isinstance(task, LauncherTask):
        return task.substeps * task.rk4_substeps, task.dt / task.substeps / task.rk4_substeps
    assert isinstance(task, NozzleTask)
    return task.substeps, task.dt / task.substeps


def rk4_on_floats(env_id: str, rounds: int, linear: bool) -> float:
    """Seconds of one env step's RK4 steps on Python floats (``rk4_floats``) for the env's joint,
    or (``linear``) for its linear part alone (the linear joint of the same J, b and
    small-signal stiffness: arithmetic the hysteretic step does too, besides its powers)."""
    joint = catalogue.spec(env_id).build_task().plant
    if linear:
        joint = NozzleParameters.linear(joint.J, joint.b, joint.small_signal_stiffness)
    params = rk4_parameters(joint.normalized())
    steps, h = rk4_steps(env_id)
    per = 20_000
    return (
        min(
            timeit.repeat(
                lambda: rk4_floats(1e-3, 0.0, 1e-3, 100.0, h, steps, params), number=per, repeat=rounds
            )
        )
        / per
    )


def restarts_per_step(env_id: str) -> float:
    """Sub-envs restarting per step of the native vector env (N envs) under the bench's random
    actions, over one episode's steps."""
    env = gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    table = bench._action_table(env.action_space, "random")[:16]
    steps = gym.spec(env_id).max_episode_steps
    ended = 0
    for k in range(steps):
        _, _, terminated, truncated, _ = env.step(table[k % len(table)])
        ended += int((terminated | truncated).sum())
    env.close()
    return ended / steps


def generator_call(draw: int, rounds: int) -> float:
    """Seconds per restart's draw: one sub-env generator filling ``draw`` float32 uniforms, as
    the vector env's restart does (N generators, one call each)."""
    rngs = [np.random.default_rng(i) for i in range(N)]
    rows = list(np.empty((N, draw), dtype=np.float32))
    single = np.float32

    def run(_: int) -> float:
        start = timeit.default_timer()
        for rng, row in zip(rngs, rows, strict=True):
            rng.random(None, single, row)
        return timeit.default_timer() - start

    return _best(run, N, rounds)


def _x(value: float) -> str:
    return f"{value:.2f}x"


def _room(budget: float, plant: float, ours: float) -> str:
    """Time per step the floor leaves beside the plant arithmetic, and what the rest takes
    today (us)."""
    return f"{(budget - plant) * 1e6:.1f} us ({(ours - plant) * 1e6:.1f} us)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5, help="best of this many rounds (default: 5)")
    args = parser.parse_args()
    rounds = args.rounds
    pendulum_run, close = bench._single_stepper("Pendulum-v1")
    pendulum = _best(pendulum_run, bench.SINGLE_ROUND_STEPS, rounds)
    close()
    cartpole = {}
    for kind in ("zero", "random"):
        run, close = bench._vector_stepper("CartPole-v1", N, kind)
        cartpole[kind] = _best(run, 500, rounds)
        close()
    exponent = catalogue.spec(next(iter(FLOORS))).build_task().rk4_params.n
    costs = power_costs(float(exponent), rounds)
    lines = [
        "# Speed floors and the env contract",
        "",
        "Command: `OMP_NUM_THREADS=1 python experiments/speed_limits.py"
        + (f" --rounds {rounds}`." if rounds != 5 else "`.")
        + " Seconds are the best of the rounds; the machine's cores are shared, so the ratios, "
        "all taken in this one run, are what to compare.",
        "",
        f"Pendulum-v1 step (through `gymnasium.make`): {pendulum * 1e6:.2f} us. CartPole-v1's "
        f"native vector env, N = {N}: {cartpole['zero'] * 1e6:.0f} us per step (zero actions), "
        f"{cartpole['random'] * 1e6:.0f} us (random actions).",
        "",
        f"Power |w|^n of the Bouc-Wen rate (n = {exponent:g}, Table 1's joint): on one Python "
        f"float, numpy's SIMD power {costs['scalar_simd'] * 1e9:.0f} ns, the C library's "
        f"`math.pow` {costs['scalar_libm'] * 1e9:.0f} ns; per element of an (N,) array, numpy's "
        f"SIMD power {costs['vector_simd'] * 1e9:.2f} ns, the C library's (`np.float_power`) "
        f"{costs['vector_libm'] * 1e9:.2f} ns. `math.pow` differs from numpy's SIMD power in the "
        f"last bit on {costs['differ_simd']:.1%} of |w| in [0, 0.1) rad and from "
        f"`np.float_power` on {costs['differ_float_power']:.1%}: a float step on `math.pow` "
        "equals an array step on `np.float_power`, never one on `np.power`.",
        "",
        "Bounds: the best ratio were everything but the named costs free, whatever the rest of "
        "the step's implementation. Single: Pendulum's step over the power calls of one step "
        "on floats plus its RK4's linear arithmetic on floats (the joint's linear part alone, "
        "which the hysteretic step computes too). "
        "Vector: CartPole's step over the power elements of one step of N envs plus, with random "
        "actions, one generator call per restart (a call that draws two numbers: the least a "
        "restart can cost; today's draws the whole episode). Beside them, today's ratios of the "
        "plant arithmetic alone (single: the joint's RK4 steps on floats, as the env's step "
        "calls them; vector: `ssme-envs bench`'s floor) and of the env (`ssme-envs bench`'s "
        "measurement, zero actions for single), and the time per step the floor leaves for "
        "everything but today's plant arithmetic (and, with random actions, a call per restart) "
        "beside what that everything takes today: negative, the floor is out of reach without "
        "faster plant arithmetic.",
        "",
        "| env | mode | actions | issue floor | powers per step | restarts per step | "
        "bound, numpy's power (today's bits) | bound, the C library's power | today: plant "
        "arithmetic alone | today: the env | room beside today's plant arithmetic at the floor "
        "(the rest today) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    verdicts = []
    for env_id, floors in FLOORS.items():
        calls = 4 * rk4_steps(env_id)[0]  # a power per RK4 stage of the hysteretic joint
        arithmetic = rk4_on_floats(env_id, rounds, linear=True)
        run, close = bench._single_stepper(env_id)
        ours = _best(run, bench.SINGLE_ROUND_STEPS, rounds)
        close()
        joint = rk4_on_floats(env_id, rounds, linear=False)
        bound = {
            power: pendulum / (calls * costs[f"scalar_{power}"] + arithmetic) for power in ("simd", "libm")
        }
        lines.append(
            f"| {env_id} | single | any | {_x(floors['single'])} | {calls} | - | {_x(bound['simd'])} | "
            f"{_x(bound['libm'])} | {_x(pendulum / joint)} | {_x(pendulum / ours)} | "
            f"{_room(pendulum / floors['single'], joint, ours)} |"
        )
        met = {power: value >= floors["single"] for power, value in bound.items()}
        plant = bench.plant_floor(env_id, N, rounds=rounds)
        restarts = restarts_per_step(env_id)
        # a restart's least cost is one call; the env draws its whole episode in it
        call = generator_call(2, rounds)
        draw = generator_call(catalogue.spec(env_id).build_task().draw_size, rounds)
        for kind in ("zero", "random"):
            restart_cost = restarts * call if kind == "random" else 0.0
            run, close = bench._vector_stepper(env_id, N, kind)
            ours = _best(run, gym.spec(env_id).max_episode_steps, rounds)
            close()
            for power in bound:
                bound[power] = cartpole[kind] / (calls * N * costs[f"vector_{power}"] + restart_cost)
                met[power] &= bound[power] >= floors["vector"]
            shown = (
                "-"
                if kind == "zero"
                else f"{restarts:.0f} x {call * 1e6:.2f} us ({draw * 1e6:.2f} us with the episode's draw)"
            )
            room = _room(cartpole[kind] / floors["vector"], plant + restart_cost, ours)
            lines.append(
                f"| {env_id} | vector N = {N} | {kind} | {_x(floors['vector'])} | {calls} | {shown} | "
                f"{_x(bound['simd'])} | {_x(bound['libm'])} | {_x(cartpole[kind] / plant)} | "
                f"{_x(cartpole[kind] / ours)} | {room} |"
            )
        verdicts.append(
            f"- {env_id}: every floor within these bounds with numpy's power: "
            f"{'yes' if met['simd'] else 'no'}; with the C library's: {'yes' if met['libm'] else 'no'}."
        )
    lines += [
        "",
        *verdicts,
        "",
        "Where neither power keeps every floor within its bound, no step written in numpy and "
        "Python meets them all while both promises hold: that would take one power function "
        "with a fast call on a float and a SIMD loop on arrays that give the same bits (a "
        "compiled extension of our own); a random-action floor beyond its bound with either "
        "power needs a cheaper way than one call per restart to draw sub-envs' episodes from "
        "their own generators.",
        "",
    ]
    write_text(RESULTS, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
