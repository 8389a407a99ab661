"""What the env contract leaves of the speed floors of ``ssme-envs bench``.

Two promises of the envs cost time: an env gives the same bits alone and in a batch (so the
float step and the array step share one power function: the joint's own,
:mod:`ssme_envs.models.joint_power`, compiled with the joint's RK4 in ``_joint_kernel.c``), and
the native vector env equals gymnasium's ``SyncVectorEnv`` (so each sub-env draws its episodes
from its own generator: where the draw kernel is built, one jump of the sub-env's PCG64 generator
per restart, made for all restarting sub-envs in one call; else one generator call per restart).
This script measures the joint's RK4
(compiled kernel and Python reference) and those calls beside Pendulum-v1 and CartPole-v1's
native vector env in the same run, and gives the best ratio each env could reach were
everything else in its step free.

    python experiments/speed_limits.py [--rounds 5]

Writes experiments/results/speed_limits.md.
"""

from __future__ import annotations

import timeit
from pathlib import Path

import gymnasium as gym
import numpy as np

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs import bench
from ssme_envs.envs import catalogue, episode_draws
from ssme_envs.envs.engine_task import EngineTask
from ssme_envs.envs.episode_draws import EpisodeDraws
from ssme_envs.envs.episode_streams import EpisodeStreams
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_task import NozzleTask
from ssme_envs.envs.task import FLOATS
from ssme_envs.models import nozzle_joint
from ssme_envs.models.nozzle import rk4_arrays, rk4_floats, rk4_parameters
from ssme_envs.outputs import write_text
from ssme_envs.script_options import int_within, script_parser

RESULTS = Path(__file__).resolve().parent / "results" / "speed_limits.md"
N = 4096  # the vector size of the floors
JOINT_ENVS = ("ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0")  # the envs with a nozzle joint
# the target floors: single over Pendulum-v1, native vector (N = 4096) over CartPole-v1's
FLOORS = {
    "ssme_envs/EngineTracking-v0": {"single": 1.5, "vector": 1.0},
    "ssme_envs/EngineThrottle-v0": {"single": 1.5, "vector": 1.0},
    "ssme_envs/NozzleTVC-v0": {"single": 0.8, "vector": 0.4},
    "ssme_envs/LauncherPitch-v0": {"single": 0.4, "vector": 0.2},
}


def _best(run, steps: int, rounds: int) -> float:
    """Best seconds per step of ``run(steps)`` over ``rounds``."""
    return min(run(steps) for _ in range(rounds)) / steps


def rk4_steps(env_id: str) -> tuple[int, float]:
    """RK4 steps of the joint per env step and their length (s)."""
    task = catalogue.spec(env_id).build_task()
    if isinstance(task, LauncherTask):
        return task.substeps * task.rk4_substeps, task.dt / task.substeps / task.rk4_substeps
    assert isinstance(task, NozzleTask)
    return task.substeps, task.dt / task.substeps


def rk4_on_floats(env_id: str, rounds: int, integrator=rk4_floats) -> float:
    """Seconds of one env step's RK4 steps on one nozzle (``integrator``: the package's
    ``rk4_floats``, or its Python reference) for the env's joint."""
    joint = catalogue.spec(env_id).build_task().plant
    params = rk4_parameters(joint.normalized())
    steps, h = rk4_steps(env_id)
    per = 20_000
    return (
        min(
            timeit.repeat(
                lambda: integrator(1e-3, 0.0, 1e-3, 100.0, h, steps, params), number=per, repeat=rounds
            )
        )
        / per
    )


def engine_on_floats(task: EngineTask, rounds: int) -> float:
    """Seconds of one engine's plant step on floats (valves and dynamics, as the single env
    runs it: the compiled float step where it was built), at the zero command of step 1."""
    plant = task.initial_plant(None)
    nominal = None if task.offsets is None else FLOATS.at(task.offsets, 1)
    per = 20_000
    step = task.plant_step
    return (
        min(timeit.repeat(lambda: step(plant, 0.0, 0.0, 1, nominal, FLOATS), number=per, repeat=rounds)) / per
    )


def plant_on_floats(env_id: str, rounds: int) -> float:
    """Seconds of one env step's plant arithmetic on one env: the engine's plant step, or the
    joint's RK4 steps."""
    task = catalogue.spec(env_id).build_task()
    if isinstance(task, EngineTask):
        return engine_on_floats(task, rounds)
    return rk4_on_floats(env_id, rounds)


def rk4_on_arrays(env_id: str, rounds: int, integrator=rk4_arrays) -> float:
    """Seconds of one env step's RK4 steps on a batch of N nozzles (``integrator``: the
    package's ``rk4_arrays``, or its numpy reference), from a spread of states."""
    params = rk4_parameters(catalogue.spec(env_id).build_task().plant.normalized())
    steps, h = rk4_steps(env_id)
    rng = np.random.default_rng(0)
    state = np.vstack([rng.normal(0.0, 0.02, N), rng.normal(0.0, 0.3, N), rng.normal(0.0, 0.01, N)])
    tau = rng.normal(0.0, 300.0, N)
    reps = 20
    return (
        min(timeit.repeat(lambda: integrator(state, tau, h, steps, params), number=reps, repeat=rounds))
        / reps
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


def kernel_start(draw: int, rounds: int) -> float:
    """Seconds per restart's draw with the draw kernel: N sub-envs' episodes of ``draw`` float32
    uniforms started in one call (each generator jumped past its draw), over N."""
    draws = EpisodeDraws(draw, [np.random.default_rng(i) for i in range(N)])
    envs = np.arange(N)

    def run(_: int) -> float:
        start = timeit.default_timer()
        draws.start(envs)
        return timeit.default_timer() - start

    return _best(run, N, rounds)


def generator_call(draw: int, rounds: int) -> float:
    """Seconds per restart's draw: one sub-env generator filling ``draw`` float32 uniforms, as
    the vector env's restart does without the draw kernel (N generators, one call each)."""
    rngs = [np.random.default_rng(i) for i in range(N)]
    rows = list(np.empty((N, draw), dtype=np.float32))
    single = np.float32

    def run(_: int) -> float:
        start = timeit.default_timer()
        for rng, row in zip(rngs, rows, strict=True):
            rng.random(None, single, row)
        return timeit.default_timer() - start

    return _best(run, N, rounds)


def noise_pairs(rounds: int) -> float:
    """Seconds of N Box-Muller pairs, float32, from their uniforms: both normals of each pair
    (cosine and sine), with the fewest of numpy's float32 ufuncs that give the envs' noise its
    bits (``references.normal_pairs``, ``episode_streams.box_muller``)."""
    rng = np.random.default_rng(0)
    u, v = rng.random(N, dtype=np.float32), rng.random(N, dtype=np.float32)
    radius, angle = np.empty(N, dtype=np.float32), np.empty(N, dtype=np.float32)
    waves = list(zip((np.cos, np.sin), np.empty((2, N), dtype=np.float32), strict=True))
    two_pi = np.float32(2.0 * np.pi)

    def run(steps: int) -> float:
        start = timeit.default_timer()
        for _ in range(steps):
            np.negative(u, out=radius)
            np.log1p(radius, out=radius)
            np.multiply(radius, -2.0, out=radius)
            np.sqrt(radius, out=radius)
            np.multiply(v, two_pi, out=angle)
            for wave, out in waves:
                wave(angle, out=out)
                np.multiply(out, radius, out=out)
        return timeit.default_timer() - start

    return _best(run, 200, rounds)


def bulk_uniforms(count: int, rounds: int) -> float:
    """Seconds to draw ``count`` float32 uniforms at numpy's own bulk speed: one generator
    filling them in one call (the envs draw theirs from N generators, a cursor each)."""
    rng, out = np.random.default_rng(0), np.empty(count, dtype=np.float32)

    def run(steps: int) -> float:
        start = timeit.default_timer()
        for _ in range(steps):
            rng.random(dtype=np.float32, out=out)
        return timeit.default_timer() - start

    return _best(run, 200, rounds)


def streams_step(rounds: int) -> float:
    """Seconds of one step of the nozzle's per-step episode streams for N envs stepping on
    together: each env's two noise uniforms from its own generator's cursors, its reference,
    and its one channel's normals (``EpisodeStreams.at``)."""
    task = catalogue.spec("ssme_envs/NozzleTVC-v0").build_task()
    draws = EpisodeDraws(task.draw_size, [np.random.default_rng(i) for i in range(N)])
    envs = np.arange(N)
    steps = min(200, task.horizon)

    def run(_: int) -> float:
        draws.start(envs)
        streams = EpisodeStreams(draws, task.stream_layout)
        streams.restart(envs)
        t = np.zeros(N, dtype=np.int64)
        start = timeit.default_timer()
        for _ in range(steps):
            t += 1
            streams.at(t, steps, True)
        return timeit.default_timer() - start

    return _best(run, steps, rounds)


def _x(value: float) -> str:
    return f"{value:.2f}x"


def _room(budget: float, plant: float, ours: float) -> str:
    """Time per step the floor leaves beside the plant arithmetic, and what the rest takes
    today (us)."""
    return f"{(budget - plant) * 1e6:.1f} us ({(ours - plant) * 1e6:.1f} us)"


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument(
        "--rounds", type=int_within(1, 100), default=5, help="best of this many rounds (default: 5)"
    )
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
        f"{cartpole['random'] * 1e6:.0f} us (random actions). {bench.kernels_used()}",
        "",
        "The joint's RK4 over one env step (its RK4 steps, a power |w|^n per stage), on one nozzle "
        "and on N nozzles, as the package runs it and as its Python reference (numpy on "
        "arrays) runs it; the same bits either way:",
        "",
        "| env | RK4 steps per env step | one nozzle | one nozzle, Python | N nozzles | N nozzles, numpy |",
        "|---|---|---|---|---|---|",
    ]
    for env_id in JOINT_ENVS:
        steps, _ = rk4_steps(env_id)
        times = (
            rk4_on_floats(env_id, rounds),
            rk4_on_floats(env_id, rounds, integrator=nozzle_joint._rk4_floats_py),
            rk4_on_arrays(env_id, rounds),
            rk4_on_arrays(env_id, min(rounds, 2), integrator=nozzle_joint._rk4_arrays_py),
        )
        lines.append(
            f"| {env_id} | {steps} | {times[0] * 1e6:.2f} us | {times[1] * 1e6:.1f} us | "
            f"{times[2] * 1e6:.0f} us | {times[3] * 1e6:.0f} us |"
        )
    lines += [
        "",
        "Bounds: the best ratio were everything but the named costs free. Single: Pendulum's step "
        "over the plant arithmetic of one env step on one env (the engine's plant step on floats, "
        "the joint's RK4 of one env step on one nozzle). Vector, zero actions: CartPole's "
        "step over `ssme-envs bench`'s plant floor (the env's plant arithmetic for N envs). "
        "Vector, random actions: the same plus each restart's draw, the least a restart can cost: "
        "with the draw kernel, its start of the episode (the sub-env's generator jumped past the "
        "draw, all restarting sub-envs in one call); without it, one generator call that draws "
        "two numbers (the vector env's draws the whole episode's uniforms). "
        "Beside them, today's ratio of the env (`ssme-envs bench`'s measurement) and the time per "
        "step the floor leaves beside those costs, with what the rest takes today.",
        "",
        "| env | mode | actions | target floor | restarts per step | bound | today: the env | "
        "room beside the named costs at the floor (the rest today) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    verdicts = []
    vectors = {}  # env id: (plant floor, today's step with random actions), seconds for N envs
    for env_id, floors in FLOORS.items():
        joint = plant_on_floats(env_id, rounds)
        verdict = {}
        for kind in ("zero", "random"):
            run, close = bench._single_stepper(env_id, kind)
            ours = _best(run, bench.SINGLE_ROUND_STEPS, rounds)
            close()
            bound = pendulum / joint
            verdict[f"single {kind}"] = (bound >= floors["single"], pendulum / ours >= floors["single"])
            lines.append(
                f"| {env_id} | single | {kind} | {_x(floors['single'])} | - | {_x(bound)} | "
                f"{_x(pendulum / ours)} | {_room(pendulum / floors['single'], joint, ours)} |"
            )
        plant = bench.plant_floor(env_id, N, rounds=rounds)
        restarts = restarts_per_step(env_id)
        size = catalogue.spec(env_id).build_task().draw_size
        call = kernel_start(size, rounds) if episode_draws.KERNEL == "compiled" else generator_call(2, rounds)
        draw = generator_call(size, rounds)
        for kind in ("zero", "random"):
            restart_cost = restarts * call if kind == "random" else 0.0
            run, close = bench._vector_stepper(env_id, N, kind)
            ours = _best(run, gym.spec(env_id).max_episode_steps, rounds)
            close()
            bound = cartpole[kind] / (plant + restart_cost)
            verdict[f"vector {kind}"] = (bound >= floors["vector"], cartpole[kind] / ours >= floors["vector"])
            if kind == "random":
                vectors[env_id] = (plant, ours)
            shown = (
                "-"
                if kind == "zero"
                else f"{restarts:.0f} x {call * 1e6:.2f} us (a generator call for the episode: "
                f"{draw * 1e6:.2f} us)"
            )
            room = _room(cartpole[kind] / floors["vector"], plant + restart_cost, ours)
            lines.append(
                f"| {env_id} | vector N = {N} | {kind} | {_x(floors['vector'])} | {shown} | "
                f"{_x(bound)} | {_x(cartpole[kind] / ours)} | {room} |"
            )
        met = [case for case, (_, today) in verdict.items() if today]
        reachable = [case for case, (within, today) in verdict.items() if within and not today]
        beyond = [case for case, (within, _) in verdict.items() if not within]
        verdicts.append(
            f"- {env_id}: met: {', '.join(met) or 'none'}; within the bound, not met: "
            f"{', '.join(reachable) or 'none'}; beyond the bound: {', '.join(beyond) or 'none'}."
        )
    lines += [
        "",
        *verdicts,
        "",
        "A floor beyond its bound is out of reach while both promises hold, whatever the rest of "
        "the step: with zero actions it would need faster plant arithmetic than the compiled "
        "kernel's; with random actions, a cheaper way than the restart's draw above to draw "
        "sub-envs' episodes from their own generators. A floor within its bound but not met "
        "needs the rest of the step (restarts and their episodes' noise and references, the "
        "task's step beside the plant, the vector bookkeeping) cut to the room the last column "
        "gives.",
        "",
        *plant_floor_line(vectors, rounds),
    ]
    write_text(RESULTS, "\n".join(lines))
    print("\n".join(lines))


def plant_floor_line(vectors: dict[str, tuple[float, float]], rounds: int) -> list[str]:
    """The section on the target "each vector step within 2x of its plant-arithmetic
    floor": what the step's sensor noise takes of the room that 2x leaves beside the plant."""
    lines = [
        "## Within 2x of the plant floor: the sensor noise in the room",
        "",
        f"A vector step within 2x of its plant floor (N = {N}) leaves the floor's own time "
        "(the room) for all beside the plant. Each step gives every env a unit sensor noise "
        "per channel, from the env's own generator: float32 uniforms turned into normals by "
        "numpy's float32 ufuncs (Box-Muller), which give the noise the bits the scalar env "
        "and `SyncVectorEnv` give it. A pair of uniforms makes two normals, so an env needs at "
        "least a uniform and half a pair per channel and step. Below, those pairs' ufuncs alone "
        "(the fewest that give those bits) and those uniforms drawn at numpy's own bulk speed "
        "(one generator filling them in one call; the envs draw from N generators), and what "
        "is left of the room for everything else: the references, the task's step beside the "
        "plant (observation, reward, termination), the actions' checks and the vector "
        "bookkeeping. Today: the step with random actions as timed above, and the floor's "
        'share of it (the figure `ssme-envs bench` gives as "of the floor", there from its '
        "own run).",
        "",
        "| env | noise channels | plant floor (the room) | the noise's ufuncs | "
        "its uniforms, numpy's bulk speed | left for the rest | today: the step | of the floor |",
        "|---|---|---|---|---|---|---|---|",
    ]
    pairs, streams = noise_pairs(rounds), streams_step(rounds)
    short = []  # the envs whose noise alone leaves no room
    for env_id, (plant, ours) in vectors.items():
        channels = catalogue.spec(env_id).build_task().n_channels
        normals, uniforms = pairs * channels / 2, bulk_uniforms(channels * N, rounds)
        left = plant - normals - uniforms
        lines.append(
            f"| {env_id} | {channels} | {plant * 1e6:.1f} us | "
            f"{normals * 1e6:.1f} us | {uniforms * 1e6:.1f} us | {left * 1e6:.1f} us | "
            f"{ours * 1e6:.0f} us | {plant / ours:.0%} |"
        )
        if left < 0.0:
            short.append(env_id)
    lines += [
        "",
        f"Where nothing is left ({', '.join(short) or 'none'}), a step within 2x of the floor "
        "would need the noise's uniforms drawn from the sub-envs' generators faster than numpy "
        "fills one generator's, and everything else in the step free. The package's fastest "
        "draw, the nozzle's per-step streams (each env's cursors on its own generator's draw), "
        f"takes {streams * 1e6:.1f} us for the N envs' two uniforms (a pair) each, their "
        f"references and one channel's normals, where numpy's bulk fill of 2 N uniforms and "
        f"the pairs' ufuncs above take {(bulk_uniforms(2 * N, rounds) + pairs) * 1e6:.1f} us. "
        "Elsewhere the last columns say "
        "how far the rest of the step is from the room.",
        "",
    ]
    return lines


if __name__ == "__main__":
    main()
