"""COMA on several workers (``ipp-train coma --workers K --backend local|ray --device``).

Fast: mission blocks flown apart give the rollout and the greedy flights of one flight, bit
for bit; a run whose missions are split into blocks trains the weights of a run that is not;
the CPU update gives the numbers of the learner before devices (recorded from it); the CLI's
errors (no Ray, --address without Ray, an address that does not answer, --device cuda without
CUDA). Slow: the same run on 2 local processes, on 2 Ray actors (a local Ray with 2 CPUs),
resumed across worker counts, with a worker or actor killed mid-run, and ``ipp-train coma
--backend ray`` end to end in a time-boxed subprocess.
"""

from __future__ import annotations

import copy
import csv
import importlib.util
import os
import platform
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import helpers
import numpy as np
import pytest
import torch
from helpers import page_faults_of_reallocation

from coma import parallel
from coma.cli import build_parser, configs_from_args
from coma.cli import main as coma_main
from coma.config import COMAConfig
from coma.learner import make_optimisers, train, update
from coma.parallel import InProcess, RunSpec, split_missions, to_channels_last
from coma.persistence import build_networks, load_policy
from coma.rollout import ACTOR_BATCH_MISSIONS, Rollout, actor_batches, collect_rollout
from coma.run_files import saved_update
from coma.validation import GreedyFlights, evaluate_greedy, fly_greedy
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.sim.mission import MissionGeometry

HAS_RAY = importlib.util.find_spec("ray") is not None
TIMING = ("transitions_per_s", "wall_s")


def tiny_env() -> EnvConfig:
    return EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 4})


def tiny_coma(**changes) -> COMAConfig:
    """Three updates of ten missions (workers get whole groups of five), seven validated."""
    return helpers.tiny_coma(**{"missions": 30, "missions_per_update": 10,
                                "minibatch_size": 80, "eval_missions": 7,
                                "target_update_transitions": 150, **changes})


def tiny_networks(variant: str = "coma"):
    torch.manual_seed(0)
    networks = build_networks(tiny_coma(variant=variant), tiny_env())
    to_channels_last(networks)
    return networks


def assert_same_rollout(a: Rollout, b: Rollout) -> None:
    for name in ("actor_obs", "critic_obs", "value_obs", "masks", "actions", "behaviour_probs",
                 "rewards"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert torch.equal(x, y), name
    np.testing.assert_array_equal(a.returns, b.returns)
    np.testing.assert_array_equal(a.final_entropy, b.final_entropy)


def assert_same_run(a, b) -> None:
    """Two TrainResults: the same progress.csv (timings aside) and the same weights in
    last.pt and best.pt."""
    assert progress_rows(a.out_dir) == progress_rows(b.out_dir)
    for name in ("last.pt", "best.pt"):
        (first, _), (second, _) = load_policy(a.out_dir / name), load_policy(b.out_dir / name)
        for network in ("actor", "critic", "value"):
            x, y = first.state_dicts()[network], second.state_dicts()[network]
            assert (x is None) == (y is None)
            for key in x or {}:
                assert torch.equal(x[key], y[key]), (name, network, key)


def progress_rows(folder: Path) -> list[dict[str, str]]:
    with open(folder / "progress.csv", newline="") as handle:
        return [{k: v for k, v in row.items() if k not in TIMING}
                for row in csv.DictReader(handle)]


def train_tiny(out: Path, **kwargs):
    return train(tiny_coma(**kwargs.pop("coma", {})), tiny_env(), out, progress=False,
                 tensorboard=False, **kwargs)


# ----------------------------------------------------------------------------- fast


def test_missions_split_into_blocks_of_whole_actor_batches():
    assert ACTOR_BATCH_MISSIONS == 5
    assert actor_batches(3, 9) == [(0, 2), (2, 7), (7, 9)]  # missions 3-4, 5-9, 10-11
    assert split_missions(0, 50, 2) == [(0, 25), (25, 25)]
    assert split_missions(50, 50, 4) == [(50, 10), (60, 15), (75, 10), (85, 15)]
    assert split_missions(3, 9, 2) == [(3, 2), (5, 7)]  # cut where a batch begins
    assert split_missions(0, 4, 2) == [(0, 4)]  # never an empty block, nor a cut batch
    assert split_missions(5, 4, 1) == [(5, 4)]


@pytest.mark.parametrize("variant", ["coma", "central_qv"])
def test_a_rollout_flown_in_blocks_is_the_rollout_flown_at_once(variant):
    networks = tiny_networks(variant)
    env = tiny_env()
    geometry = MissionGeometry(env)
    whole = collect_rollout(networks, env, geometry, 3, 3, 12, 0.5)  # missions 3-14
    blocks = [collect_rollout(networks, env, geometry, 3, first, count, 0.5)
              for first, count in split_missions(3, 12, 3)]
    assert len(blocks) == 3
    assert_same_rollout(Rollout.concatenate(blocks), whole)
    # A mission's actions are its own: flown in another call, missions 10-14 sample what
    # they sampled above ...
    alone = collect_rollout(networks, env, geometry, 3, 10, 5, 0.5)
    assert torch.equal(alone.actions, whole.actions[7:])
    assert torch.equal(alone.behaviour_probs, whole.behaviour_probs[7:])
    # ... and the streams differ between runs (the actions are sampled).
    other_seed = collect_rollout(networks, env, geometry, 4, 3, 12, 0.5)
    assert not torch.equal(other_seed.actions, whole.actions)


def test_greedy_flights_in_blocks_score_as_one_flight():
    networks = tiny_networks()
    env = tiny_env()
    geometry = MissionGeometry(env)
    blocks = GreedyFlights.concatenate([fly_greedy(networks.actor, env, geometry, 2, first, n)
                                        for first, n in split_missions(0, 8, 2)])
    assert blocks.scores() == evaluate_greedy(networks.actor, env, geometry, 2, 8)
    assert blocks.entropy.shape == (8, env.team.budget + 1) and blocks.rewards.shape == (8, 4)


class SplitInProcess(InProcess):
    """The learner's process flies each call's missions in three blocks, one after another:
    the learner's path through several workers without starting any."""

    count = 3


def test_a_run_split_into_blocks_trains_the_same_weights(tmp_path, monkeypatch):
    whole = train_tiny(tmp_path / "whole", coma={"variant": "central_qv"})

    def split_workers(spec, workers, backend, address, geometries):
        return SplitInProcess(spec, geometries)

    monkeypatch.setattr("coma.learner.make_workers", split_workers)
    split = train_tiny(tmp_path / "split", coma={"variant": "central_qv"})
    assert_same_run(whole, split)


def synthetic_rollout(networks, e: int = 3, t: int = 4) -> Rollout:
    """A rollout of seeded random tensors: the update's input without the simulator."""
    g = torch.Generator().manual_seed(7)
    n = networks.env_config.team.n_agents
    grid = networks.env_config.world.grid_points

    def planes(module):
        return torch.rand(e, n, t, module.in_channels, grid, grid, generator=g)

    masks = torch.rand(e, n, t, 6, generator=g) > 0.3
    masks[..., 0] = True
    scores = torch.rand(e, n, t, 6, generator=g).masked_fill(~masks, -1)
    return Rollout(actor_obs=planes(networks.actor), critic_obs=planes(networks.critic),
                   value_obs=None if networks.value is None else planes(networks.value),
                   masks=masks, actions=scores.argmax(-1),
                   behaviour_probs=0.2 + 0.8 * torch.rand(e, n, t, generator=g),
                   rewards=torch.randn(e, t, generator=g), returns=np.zeros(e),
                   final_entropy=np.zeros(e))


# Recorded from coma.learner.update as it was before --device (commit 6fde235), on
# synthetic_rollout: two updates of the coma variant. The CPU path must keep these numbers
# (bit for bit on the machine they were recorded on; the tolerance is for other CPUs).
BEFORE_DEVICES = [
    {"critic_loss": 2.7043240467707315, "actor_loss": 0.11446813804407914,
     "advantage_std": 0.13156399751702944, "policy_entropy": 1.509250819683075,
     "critic_grad_norm": 1.5160272717475891, "actor_grad_norm": 0.11920485024650891},
    {"critic_loss": 2.6745184461275735, "actor_loss": 0.10756516852416098,
     "advantage_std": 0.12863401075204214, "policy_entropy": 1.4873118996620178,
     "critic_grad_norm": 1.4661826888720195, "actor_grad_norm": 0.1094531665245692},
]
BEFORE_DEVICES_SUMS = {"actor": -9.141991517878523, "critic": 5.622392437122471}


def test_the_cpu_update_gives_the_numbers_of_the_learner_before_devices():
    env = tiny_env()
    config = COMAConfig(width=8, hidden=16, minibatch_size=10, epochs=2, warm_start="")
    torch.manual_seed(0)
    networks = build_networks(config, env)
    to_channels_last(networks)
    target = copy.deepcopy(networks.critic)
    optimisers = make_optimisers(networks)
    generator = torch.Generator().manual_seed(3)
    rollout = synthetic_rollout(networks)
    assert rollout.to("cpu") is rollout  # a CPU learner trains on the rollout's own tensors
    losses = [update(networks, target, optimisers, rollout, 0.1, generator) for _ in range(2)]
    for got, want in zip(losses, BEFORE_DEVICES, strict=True):
        assert got.keys() == want.keys()
        for key in want:
            assert got[key] == pytest.approx(want[key], rel=1e-4), key
    with torch.no_grad():
        for name, want in BEFORE_DEVICES_SUMS.items():
            total = float(sum(p.double().sum() for p in getattr(networks, name).parameters()))
            # Adam's normalised step moves a parameter with a near-zero gradient by up to the
            # learning rate whichever way a last-bit difference tips it, so on another CPU
            # (AVX-512 against AVX2) the sums drift by ~3e-4; the two updates move them by
            # 0.13 (actor) and 1.3 (critic), which a wrong update would not match to 1e-3.
            assert total == pytest.approx(want, abs=1e-3), name


needs_no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available here")


@needs_no_cuda
def test_cuda_without_cuda_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "run"
    with pytest.raises(ValueError, match="device 'cuda'"):
        train_tiny(out, device="cuda")
    assert not out.exists()
    assert coma_main(["--out", str(out), "--device", "cuda", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ipp-train coma: error: device 'cuda': ") and "--device cpu" in err
    assert len(err.splitlines()) == 1 and not out.exists()


def test_bad_compute_flags_exit_2_naming_the_value(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    assert coma_main(["--out", str(out), "--device", "tpu"]) == 2
    assert "device 'tpu': choose cpu or cuda" in capsys.readouterr().err
    assert coma_main(["--out", str(out), "--address", "127.0.0.1:6379"]) == 2
    assert capsys.readouterr().err.strip() == \
        "ipp-train coma: error: --address needs --backend ray"
    with pytest.raises(SystemExit) as exit_:
        coma_main(["--out", str(out), "--workers", "0"])
    assert exit_.value.code == 2 and "--workers" in capsys.readouterr().err
    with pytest.raises(ValueError, match="workers = 0"):
        train_tiny(out, workers=0)
    with pytest.raises(ValueError, match="backend must be one of local, ray, got 'dask'"):
        train_tiny(out, backend="dask")
    with pytest.raises(ValueError, match="address is only used with backend='ray'"):
        train_tiny(out, address="127.0.0.1:6379")
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    assert coma_main(["--out", str(out), "--backend", "ray", "--workers", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("ipp-train coma: error: ")
    assert 'pip install -c constraints.txt -e ".[ray]"' in err
    assert not out.exists()


@pytest.mark.skipif(not HAS_RAY, reason="Ray is not installed")
def test_an_address_where_nothing_answers_fails_within_seconds(tmp_path, capsys):
    out = tmp_path / "run"
    start = time.monotonic()
    assert coma_main(["--out", str(out), "--backend", "ray", "--address", "127.0.0.1:1"]) == 2
    assert time.monotonic() - start < 10
    err = capsys.readouterr().err.strip()
    assert err.startswith("ipp-train coma: error: no Ray cluster answers at '127.0.0.1:1'")
    assert not out.exists()


# ----------------------------------------------------------------------------- slow


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    """The tiny run in this process (one worker)."""
    return train_tiny(tmp_path_factory.mktemp("reference") / "run")


@pytest.mark.slow
def test_two_local_processes_train_the_same_weights_and_resume_with_one(reference_run,
                                                                       tmp_path):
    both = train_tiny(tmp_path / "k2", workers=2)
    assert_same_run(reference_run, both)
    # Begun on two processes, continued in this one: the same run again.
    out = tmp_path / "mixed"
    train_tiny(out, workers=2, max_updates=2)
    assert_same_run(reference_run, train_tiny(out, resume=True))


def kill_workers_and_fly(make_pool) -> None:
    """Rollouts on a pool of 2 whose workers are killed (between two calls, then during
    one) are the rollout flown in this process; the killed workers are replaced."""
    networks = tiny_networks()
    env = tiny_env()
    spec = RunSpec(tiny_coma(), env, (env,), (env,), 0)
    reference = InProcess(spec).rollout(networks, 0, 0, 24, 0.3)
    with make_pool(spec, 2) as pool:
        pool.rollout(networks, 0, 30, 2, 0.3)  # both workers up
        victim = pool.pids()[0]
        os.kill(victim, signal.SIGKILL)  # between two calls
        assert_same_rollout(pool.rollout(networks, 0, 0, 24, 0.3), reference)
        assert victim not in pool.pids()
        victim = pool.pids()[-1]  # during a call (if it lasts 50 ms; else before the next)
        killer = threading.Timer(0.05, os.kill, (victim, signal.SIGKILL))
        killer.start()
        try:
            assert_same_rollout(pool.rollout(networks, 0, 0, 24, 0.3), reference)
        finally:
            killer.join()
        assert_same_rollout(pool.rollout(networks, 0, 0, 24, 0.3), reference)
        assert victim not in pool.pids()


@pytest.mark.slow
def test_a_killed_local_worker_is_replaced_and_its_missions_flown_again():
    kill_workers_and_fly(parallel.ProcessWorkers)


@pytest.fixture(scope="module")
def ray_cluster():
    """One local Ray with 2 CPUs for the module's Ray tests (as CI has)."""
    if not HAS_RAY:
        pytest.skip('Ray is not installed (pip install -c constraints.txt -e ".[ray]")')
    import ray

    from ipp_toolkit.runs.ray_backend import start_local

    start_local(2)
    try:
        yield ray
    finally:
        ray.shutdown()


@pytest.mark.slow
def test_two_ray_actors_train_the_weights_of_one_process(ray_cluster, reference_run,
                                                        tmp_path):
    result = train_tiny(tmp_path / "ray", workers=2, backend="ray")
    assert ray_cluster.is_initialized()  # the module's Ray is used, and left running
    with pytest.raises(ValueError, match="has 2 CPU.*fewer than the 3 workers"):
        train_tiny(tmp_path / "too-many", workers=3, backend="ray")  # would wait forever
    assert not (tmp_path / "too-many").exists()
    assert_same_run(reference_run, result)
    deadline = time.monotonic() + 30  # the actors are gone: their CPUs come back
    while ray_cluster.available_resources().get("CPU", 0) < 2:
        assert time.monotonic() < deadline, ray_cluster.available_resources()
        time.sleep(0.5)


@pytest.mark.slow
def test_igs_reference_flies_on_the_cluster_at_the_address(ray_cluster, tmp_path, monkeypatch):
    """With --address, ``selection = worst_vs_ig``'s IG reference flies on the cluster (before
    the actors take its CPUs) and gives the numbers of local processes."""
    from coma import learner

    calls = []

    def recording(*args, **kwargs):
        calls.append((kwargs["backend"], kwargs["address"]))
        return learner_reference(*args, **kwargs)

    learner_reference = learner.reference_scores
    monkeypatch.setattr(learner, "reference_scores", recording)
    address = ray_cluster.get_runtime_context().gcs_address
    coma = {"selection": "worst_vs_ig"}
    on_ray = train_tiny(tmp_path / "ray", workers=2, backend="ray", address=address,
                        coma=coma)
    here = train_tiny(tmp_path / "here", coma=coma)
    assert calls == [("ray", address), ("local", None)]
    assert_same_run(here, on_ray)  # the gaps to IG (progress.csv) and the selected weights


@pytest.mark.slow
def test_a_killed_ray_actor_is_restarted_and_its_call_run_again(ray_cluster):
    kill_workers_and_fly(parallel.RayWorkers)


@pytest.mark.slow
@pytest.mark.skipif(not HAS_RAY, reason="Ray is not installed")
def test_ipp_train_coma_on_a_local_ray_end_to_end(tmp_path):
    """``ipp-train coma --workers 2 --backend ray`` in a fresh process (its own local Ray with
    2 CPUs), stopped after 2 updates and resumed, trains the weights that this process trains
    from the same flags. Time-boxed: each command must end within 5 minutes."""
    out = tmp_path / "run"
    (tmp_path / "env.yaml").write_text("team:\n  budget: 4\n")
    flags = ["--agents", "2", "--resolution", "1.0", "--config", str(tmp_path / "env.yaml"),
             "--warm-start", "none", "--no-progress", "--set", "width=8", "--set", "hidden=16",
             "--set", "missions_per_update=10", "--set", "minibatch_size=80",
             "--set", "epochs=1", "--set", "eval_every=1", "--set", "eval_missions=7",
             "--set", "target_update_transitions=150"]
    script = "import sys; from reports.cli import train_main; sys.exit(train_main())"
    for missions, resume in (("20", []), ("30", ["--resume"])):
        done = subprocess.run([sys.executable, "-c", script, "coma", "--out", str(out),
                               "--workers", "2", "--backend", "ray", *flags, "--missions",
                               missions, *resume], capture_output=True, text=True,
                              timeout=300, cwd=Path(__file__).parents[1])
        assert done.returncode == 0, done.stderr[-2000:]
    coma_config, env_config = configs_from_args(build_parser().parse_args(
        ["--out", "unused", *flags, "--missions", "30"]))
    here = train(coma_config, env_config, tmp_path / "here", progress=False,
                 tensorboard=False)
    trained, _ = load_policy(out / "last.pt")
    assert here.updates == 3 and saved_update(out / "last.pt") == "3"
    for key, value in load_policy(here.last_checkpoint)[0].actor.state_dict().items():
        assert torch.equal(trained.actor.state_dict()[key], value), key


@pytest.mark.slow  # a fresh process trains; test_evaluation tests the allocator setting fast
@pytest.mark.skipif(platform.libc_ver()[0] != "glibc",
                    reason="retain_freed_memory sets glibc's allocator")
def test_the_trainer_process_keeps_freed_memory_for_reuse(tmp_path):
    # After train(), allocating again what was just freed costs no new pages.
    setup = f"""
from coma.config import COMAConfig
from coma.learner import train
from ipp_toolkit.config.schema import EnvConfig
env = EnvConfig().replace(world={{"resolution": 1.0}}, team={{"n_agents": 2, "budget": 3}})
coma = COMAConfig(width=8, hidden=16, missions=2, missions_per_update=2, minibatch_size=40,
                  epochs=1, eval_every=1, eval_missions=1, checkpoint_every=1,
                  target_update_transitions=100, warm_start="")
train(coma, env, {str(tmp_path / "run")!r}, progress=False, tensorboard=False)
"""
    plain, trained = page_faults_of_reallocation(), page_faults_of_reallocation(setup)
    assert plain > 1000 and trained < plain / 10, (plain, trained)
