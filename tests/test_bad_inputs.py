"""Bad inputs and faults: each refused with a clear error naming the bad thing, exit code 2
from the command line, and nothing written."""

from __future__ import annotations

import importlib

import pytest
import torch

from coma.persistence import resolve_policy
from reports.cli import compare_main, train_main


@pytest.fixture(scope="module")
def broken_policies(tmp_path_factory) -> dict[str, str]:
    folder = tmp_path_factory.mktemp("policies")
    empty = folder / "empty.pt"
    empty.write_bytes(b"")
    garbage = folder / "garbage.pt"
    garbage.write_bytes(b"\x00not a torch file")
    data = torch.load(resolve_policy("shipped:paper-actor"), weights_only=True)
    name = next(iter(data["critic"]))
    data["critic"][name] = torch.full_like(data["critic"][name], float("inf"))
    infinite = folder / "infinite.pt"
    torch.save(data, infinite)
    return {"empty": str(empty), "garbage": str(garbage), "infinite": str(infinite)}


@pytest.mark.parametrize("kind, message", [
    ("empty", "is empty (0 bytes)"),
    ("garbage", "is corrupt or not a plain-weights file"),
    ("infinite", "holds non-finite values (NaN or inf) in critic."),
])
@pytest.mark.parametrize("planner", ["coma", "ppo"])
def test_compare_refuses_broken_checkpoints(broken_policies, tmp_path, capsys, monkeypatch,
                                            kind, message, planner):
    path = broken_policies[kind]
    out = tmp_path / "out"
    workers = ["--workers", "1"]
    if (planner, kind) == ("coma", "infinite"):
        # With ipp-compare's default workers, as in a fresh process (this one may hold the
        # planners already): a worker builds and checks the planners, and its error is the
        # refusal here. The other cases check their files in this process, sparing each a
        # worker's start (torch); the checks are the same.
        module = importlib.import_module("reports.compare")  # not the function reports exports
        monkeypatch.setattr(module, "planners_in_process", lambda: [])
        workers = []
    assert compare_main(["--planners", f"ig,{planner}={path}", "--out", str(out),
                         *workers]) == 2
    err = capsys.readouterr().err
    assert "ipp-compare: error:" in err and path in err
    if planner == "coma" or kind == "empty":
        assert message in err
    assert not out.exists()


@pytest.mark.parametrize("kind", ["empty", "infinite"])
def test_train_init_refuses_broken_checkpoints(broken_policies, tmp_path, capsys, kind):
    out = tmp_path / "run"
    code = train_main(["coma", "--out", str(out), "--init", broken_policies[kind],
                       "--feature", "gain=true", "--set", "gain_prior=50"])
    assert code == 2
    assert broken_policies[kind] in capsys.readouterr().err
    assert not out.exists()


def test_unknown_shipped_policy_is_named(tmp_path, capsys):
    assert compare_main(["--planners", "coma=shipped:best", "--workers", "1",
                         "--out", str(tmp_path / "o")]) == 2
    assert "unknown shipped policy 'best'" in capsys.readouterr().err


@pytest.mark.parametrize(("main", "argv", "named"), [
    (compare_main, ["--planners", "ig,coma_mixed"], "planner 'coma_mixed' was removed"),
    (compare_main, ["--planners", "ig,coma=shipped:mixed"],
     "shipped policy 'shipped:mixed' of the coma planner was removed"),
    (lambda argv: train_main(["coma", *argv]), ["--init", "shipped:mixed"],
     "shipped policy 'shipped:mixed' of the coma planner was removed"),
    (lambda argv: train_main(["coma", *argv]), ["--preset", "mixed"],
     "argument --preset: the recipe of shipped:mixed was removed"),
])
def test_removed_coma_mixed_is_refused_with_what_to_use_instead(tmp_path, capsys, main, argv,
                                                                named):
    from ipp_toolkit.planning import available_planners

    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    line = err.splitlines()[-1]  # ipp-compare prints the setting first
    # The hint names the replacement: the default coma (whatever policy it flies today).
    assert ": error: " in line and named in line
    assert "use coma (its default policy)" in line
    assert not out.exists()
    assert "coma_mixed" not in available_planners()


def test_a_result_folder_is_a_growing_set(tmp_path, capsys, placeholder_figures):
    import csv

    out = tmp_path / "out"
    common = ["--agents", "2", "--resolution", "1.0", "--budget", "2", "--workers", "1",
              "--no-progress", "--out", str(out)]
    assert compare_main(["--planners", "ig,random", "--trials", "2"] + common) == 0
    assert compare_main(["--planners", "coverage", "--trials", "2"] + common) == 0

    def planners() -> set[str]:
        with open(out / "results.csv", newline="") as handle:
            return {row["planner"] for row in csv.DictReader(handle)}

    assert planners() == {"ig", "random", "coverage"}
    summary = (out / "summary.md").read_text()
    assert all(f"| {p} |" in summary for p in ("ig", "random", "coverage"))
    assert "Δ vs ig" in summary  # the stored reference still gives the paired column
    # More missions than the earlier planners hold: only complete planners are tabulated.
    assert compare_main(["--planners", "random", "--trials", "3"] + common) == 0
    assert planners() == {"random"}


@pytest.mark.parametrize("trainer", ["coma", "ppo"])
def test_resume_without_a_run_is_refused(tmp_path, capsys, trainer):
    out = tmp_path / "nothing-here"
    assert train_main([trainer, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "nothing to resume" in err and "nothing-here" in err


def test_unknown_reset_option_is_named():
    from ipp_toolkit.config.schema import EnvConfig
    from ipp_toolkit.env import IPPEnv

    env = IPPEnv(EnvConfig().replace(world={"resolution": 1.0}))
    with pytest.warns(UserWarning, match=r"unknown reset option\(s\) \['misson'\]"):
        env.reset(seed=0, options={"misson": 3})


@pytest.mark.parametrize("argv, message", [
    (["--terrain", "blob"], "terrain is one of split"),
    (["--set", "validation_terrains=split+blob"], "unknown terrain kind"),
    (["--set", "validation_resolutions=0.1+0"], "validation_resolutions = (0.1, 0.0)"),
    (["--set", "selection=best"], "selection"),
    (["--set", "residual_penalty=-1"], "residual_penalty"),
    (["--init", "shipped:nope"], "unknown shipped policy 'nope'"),
    (["--agents", "3", "--config", "/nonexistent/mission.yaml"], "cannot read config file"),
])
def test_train_coma_bad_settings_exit_2_and_write_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "run"
    assert train_main(["coma", "--out", str(out)] + argv) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


#: Each trainer's command, and the shared mission flags it takes (ipp-compare's value types).
TRAINER_FLAGS = {
    "coma": (["coma"], ("--agents", "--missions", "--comm", "--resolution")),
    "ppo": (["ppo"], ("--agents", "--comm", "--resolution")),
    "sb3": (["sb3", "--algo", "A2C"], ("--agents", "--comm", "--resolution")),
    "rllib": (["rllib"], ("--agents", "--comm", "--resolution")),
    "prior": (["prior"], ("--missions", "--resolution")),
}
#: A bad value of each flag, and what ipp-compare says of it.
BAD_FLAG_VALUES = [
    ("--agents", "0", "must be an integer >= 1, got '0'"),
    ("--agents", "x", "must be an integer >= 1, got 'x'"),
    ("--missions", "0", "must be an integer >= 1, got '0'"),
    ("--missions", "2.5", "must be an integer >= 1, got '2.5'"),
    ("--comm", "-3", "--comm must be >= 0 metres or 'inf', got '-3'"),
    ("--comm", "nan", "--comm must be >= 0 metres or 'inf', got 'nan'"),
    ("--comm", "far", "--comm must be metres or 'inf', got 'far'"),
    ("--resolution", "0", "must be a positive number, got '0'"),
    ("--resolution", "inf", "must be a positive number, got 'inf'"),
]


@pytest.mark.parametrize("trainer, flag, value, message", [
    (trainer, flag, value, message) for trainer, (_, flags) in sorted(TRAINER_FLAGS.items())
    for flag, value, message in BAD_FLAG_VALUES if flag in flags])
def test_train_bad_mission_flags_exit_2_as_in_compare(tmp_path, capsys, trainer, flag, value,
                                                      message):
    command = TRAINER_FLAGS[trainer][0]
    out = tmp_path / "run"
    assert train_main([*command, "--out", str(out), flag, value]) == 2
    err = capsys.readouterr().err
    assert f"argument {flag}: {message}" in err, err
    assert not out.exists()
    # ipp-compare says the same of it.
    if flag != "--missions":
        assert compare_main([flag, value, "--out", str(tmp_path / "compare")]) == 2
        assert f"argument {flag}: {message}" in capsys.readouterr().err
        assert not (tmp_path / "compare").exists()


@pytest.mark.parametrize("trainer", [name for name, (_, flags) in sorted(TRAINER_FLAGS.items())
                                     if "--comm" in flags])
def test_train_parsers_take_inf_comm_as_compare_does(trainer):
    """An unlimited range is written ``inf`` in every command."""
    import importlib

    from reports.cli import TRAINERS

    command = TRAINER_FLAGS[trainer][0]
    module = importlib.import_module(TRAINERS[trainer])
    parser = module.build_parser() if trainer == "coma" else module._parser()
    args = parser.parse_args([*command[1:], "--out", "x", "--comm", "inf", "--agents", "3"])
    assert args.comm == float("inf") and args.agents == 3


@pytest.mark.parametrize("command, prefix", [
    (["prior"], "--agents"),  # a prefix of --agents-per-step
    (["prior"], "--comm"),  # a prefix of --comm-ranges
    (["coma"], "--comm-r"),  # a prefix of --comm-ranges
    (["ppo"], "--time-l"),  # a prefix of --time-limit
    (["sb3", "--algo", "A2C"], "--time-l"),
    (["rllib"], "--iter"),  # a prefix of --iterations
    (["compare"], "--plan"),  # a prefix of --planners
    (["study", "generalisation"], "--team"),  # a prefix of --team-families
])
def test_a_prefix_of_a_flag_is_refused_not_taken_for_it(tmp_path, capsys, command, prefix):
    """``ipp-train prior --agents 4`` must not quietly set ``--agents-per-step``."""
    from reports.study_cli import main as study_main

    out = tmp_path / "run"
    if command[0] == "compare":
        code = compare_main([prefix, "ig", "--out", str(out)])
    elif command[0] == "study":
        code = study_main([*command[1:], prefix, "split", "--out", str(out)])
    else:
        code = train_main([*command, prefix, "4", "--out", str(out)])
    assert code == 2
    assert f"unrecognized arguments: {prefix}" in capsys.readouterr().err
    assert not out.exists()


#: Each comma-list flag (the command, the flag), a bad list, and what is said of its bad item:
#: the words of the single-value type (ipp_toolkit.runs.cli_flags), then the whole list.
BAD_LISTS = [
    (["train", "coma"], "--team-sizes", "2,x,8", "must be an integer >= 1, got 'x' (in '2,x,8')"),
    (["train", "coma"], "--team-sizes", "2,0", "must be an integer >= 1, got '0' (in '2,0')"),
    (["train", "coma"], "--team-sizes", "2,,8", "'2,,8' has an empty value"),
    (["train", "coma"], "--comm-ranges", "0,far",
     "--comm-ranges must be metres or 'inf', got 'far' (in '0,far')"),
    (["train", "coma"], "--comm-ranges", "0,-5",
     "--comm-ranges must be >= 0 metres or 'inf', got '-5' (in '0,-5')"),
    (["train", "prior"], "--team-sizes", "2,x", "must be an integer >= 1, got 'x' (in '2,x')"),
    (["train", "prior"], "--comm-ranges", "25,nan",
     "--comm-ranges must be >= 0 metres or 'inf', got 'nan' (in '25,nan')"),
    (["study", "robustness"], "--agents", "2,four", "must be an integer >= 1, got 'four'"),
    (["study", "robustness"], "--comm", "0,far", "--comm must be metres or 'inf', got 'far'"),
    (["study", "robustness"], "--failures", "0,-1", "must be an integer >= 0, got '-1'"),
    (["study", "credit"], "--seeds", "0,x", "must be an integer >= 0, got 'x' (in '0,x')"),
    (["study", "sweep"], "--seeds", "1.5", "must be an integer >= 0, got '1.5'"),
]


@pytest.mark.parametrize("command, flag, value, message", BAD_LISTS)
def test_a_bad_item_of_a_list_flag_is_named_with_exit_2(tmp_path, capsys, command, flag, value,
                                                        message):
    from reports.cli import study_main

    out = tmp_path / "run"
    argv = [*command[1:], flag, value, "--out", str(out)]
    code = train_main(argv) if command[0] == "train" else study_main(argv)
    assert code == 2
    err = capsys.readouterr().err
    assert f"argument {flag}: {message}" in err, err
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("command, flag, text, values", [
    ("coma", "--team-sizes", "2,4,8", [2, 4, 8]),
    ("coma", "--team-sizes", "2, 4", [2, 4]),
    ("coma", "--comm-ranges", "0,25,inf", [0.0, 25.0, float("inf")]),
    ("prior", "--team-sizes", "3", [3]),
    ("prior", "--comm-ranges", "12.5,inf", [12.5, float("inf")]),
    ("study", "--agents", "2,4,8", [2, 4, 8]),
    ("study", "--comm", "0,25,inf", [0.0, 25.0, float("inf")]),
    ("study", "--failures", "0,1", [0, 1]),
    ("study", "--seeds", "0,1,2", [[0, 1, 2]]),
])
def test_good_lists_still_parse(command, flag, text, values):
    from baselines.field_prior.training import _parser as prior_parser
    from coma.cli import build_parser
    from reports.study_cli import _study_parser

    argv = ["--out", "x", flag, text]
    if command == "study":
        args = _study_parser().parse_args(["robustness", *argv])
    else:
        args = (build_parser() if command == "coma" else prior_parser()).parse_args(argv)
    assert getattr(args, flag[2:].replace("-", "_")) == values


def test_list_flag_defaults_are_read_as_lists():
    from baselines.field_prior.training import PriorTrainingConfig
    from baselines.field_prior.training import _parser as prior_parser

    args = prior_parser().parse_args(["--out", "x"])
    assert tuple(args.team_sizes) == PriorTrainingConfig().team_sizes
    assert args.comm_ranges == [0.0, 25.0, float("inf")]


@pytest.mark.parametrize("argv, message", [
    (["--families", "blob"], "unknown terrain kind"),
    (["--planners", "random,coverage"], "reference planner 'ig'"),
    (["--planners", "ig,astar"], "unknown planner 'astar'"),
])
def test_study_generalisation_bad_input_exits_2(tmp_path, capsys, argv, message):
    from reports.cli import study_main

    out = tmp_path / "study"
    assert study_main(["generalisation", "--out", str(out), "--trials", "1", "--no-progress"]
                      + argv) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["--agents", "0"], "agents"),
    (["--comm", "-5"], "--comm"),
    (["--resolution", "0.3"], "whole number of cells"),
    (["--config", "/nonexistent.yaml"], "cannot read config file"),
])
def test_simulate_bad_input_exits_2(tmp_path, capsys, argv, message):
    from reports.cli import simulate_main

    out = tmp_path / "sim"
    try:
        code = simulate_main(argv + ["--out", str(out)])
    except SystemExit as exit_:  # argparse refuses malformed flags itself
        code = exit_.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow  # in this process, fast: test_evaluation's interrupted run resumes
def test_a_killed_compare_resumes_without_loss_or_duplicates(tmp_path):
    import csv
    import os
    import signal
    import subprocess
    import sys
    import time

    # Missions long enough in number that the run cannot end between two looks at the
    # folder: results come in bursts (the main process draws a figure meanwhile) and, at 40
    # missions, a fast machine wrote all 80 between two looks.
    trials = 100
    argv = ["--agents", "2", "--resolution", "1.0", "--budget", "3", "--trials", str(trials),
            "--planners", "ig,random", "--workers", "2", "--no-progress"]
    script = ("import sys; from reports.cli import compare_main; "
              "sys.exit(compare_main(sys.argv[1:]))")
    killed = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "-c", script, *argv, "--out", str(killed)],
                               start_new_session=True, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if len(list(killed.glob("shards/*/mission_*.json"))) >= 10:
            break
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)  # the main process and its pool workers
    process.wait()
    stored = len(list(killed.glob("shards/*/mission_*.json")))
    assert 0 < stored < 2 * trials, stored  # killed mid-run, with missions stored
    assert compare_main(argv + ["--out", str(killed)]) == 0  # resumes
    assert compare_main(argv + ["--out", str(tmp_path / "whole")]) == 0

    def rows(folder):
        with open(folder / "results.csv", newline="") as handle:
            return [{k: v for k, v in row.items() if k != "plan_ms"}
                    for row in csv.DictReader(handle)]

    resumed, whole = rows(killed), rows(tmp_path / "whole")
    keys = [(r["planner"], r["mission"], r["step"]) for r in resumed]
    assert len(keys) == len(set(keys)) == 2 * trials * 4  # nothing lost, nothing twice
    assert resumed == whole


def _children(pid: int) -> list[int]:
    """PIDs whose parent is ``pid`` (read from /proc)."""
    from pathlib import Path

    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    from pathlib import Path

    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_compare(out, argv):
    import signal
    import subprocess
    import sys
    import time

    script = ("import sys; from reports.cli import compare_main; "
              "sys.exit(compare_main(sys.argv[1:]))")
    # The child must take Ctrl-C as a terminal would: a test run started in the background
    # (nohup, `&`) passes SIGINT down as ignored, and Python keeps it ignored.
    process = subprocess.Popen([sys.executable, "-c", script, *argv, "--out", str(out)],
                               start_new_session=True, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if len(list(out.glob("shards/*/mission_*.json"))) >= 4:
            break
        time.sleep(0.05)
    return process


def test_ctrl_c_in_ipp_compare_exits_130_with_one_line_and_keeps_the_missions(tmp_path, capsys,
                                                                             monkeypatch):
    """In this process (the test below sends the signal to a real run and its workers): a
    KeyboardInterrupt while missions fly ends ipp-compare with exit 130 and one line saying
    how to continue; the missions already flown stay stored."""
    from baselines.heuristics.random_planner import RandomPlanner
    from ipp_toolkit.world.seeding import planner_seed

    reset = RandomPlanner.reset

    def interrupted_at_the_second_mission(self, config, seed):
        if seed == planner_seed(0, 1):  # mission 1 of run seed 0
            raise KeyboardInterrupt
        reset(self, config, seed)

    monkeypatch.setattr(RandomPlanner, "reset", interrupted_at_the_second_mission)
    out = tmp_path / "out"
    assert compare_main(["--agents", "2", "--resolution", "1.0", "--budget", "2", "--trials",
                         "3", "--planners", "random", "--workers", "1", "--no-progress",
                         "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("interrupted") == 1
    assert "run the same command again" in err and str(out) in err
    assert [p.name for p in out.glob("shards/*/mission_*.json")] == ["mission_00000.json"]


@pytest.mark.slow  # in this process, fast: the test above
@pytest.mark.skipif(not __import__("pathlib").Path("/proc/self/stat").exists(),
                    reason="reads /proc")
def test_ctrl_c_prints_one_line_and_a_killed_main_leaves_no_workers(tmp_path):
    import os
    import signal
    import time

    argv = ["--agents", "2", "--resolution", "1.0", "--budget", "3", "--trials", "200",
            "--planners", "ig,random", "--workers", "2", "--no-progress"]
    process = _start_compare(tmp_path / "first", argv)
    workers = _children(process.pid)
    os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C sends: the whole process group
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130
    assert "Traceback" not in err and err.count("interrupted") == 1
    assert "run the same command again" in err
    deadline = time.monotonic() + 10  # terminated workers are gone within moments
    while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
        time.sleep(0.1)
    assert not [pid for pid in workers if _alive(pid)]

    process = _start_compare(tmp_path / "killed", argv)
    workers = [pid for pid in _children(process.pid) if _alive(pid)]
    assert workers
    os.kill(process.pid, signal.SIGKILL)  # the main process only
    process.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
        time.sleep(0.1)
    assert not [pid for pid in workers if _alive(pid)]


def test_a_worker_starting_after_its_main_process_died_exits_at_once():
    """A pool worker still importing when the main process is killed is already an orphan
    when its initializer runs: it must leave, not wait for tasks that never come."""
    import subprocess
    import sys

    script = ("import os, time; from ipp_toolkit.runs.process_pool import guard_worker; "
              "guard_worker(os.getppid() + 1 if os.getppid() > 1 else 2); time.sleep(30)")
    finished = subprocess.run([sys.executable, "-c", script], timeout=20)
    assert finished.returncode == 1


def _yaml_file(tmp_path, text: str):
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("argv, message", [
    (["--planners", "ig,astar"], "unknown planner 'astar'"),
    (["--trials", "0"], "--trials"),
    (["--comm", "far"], "--comm"),
    (["--threshold", "3"], "in a raster's units, but the terrain is 'split'"),
    (["--terrain", "/nonexistent/field.tif", "--threshold", "25"], "/nonexistent/field.tif"),
    (["--terrain", "fractal", "--threshold-quantile", "1.5"], "threshold_quantile"),
    (["--namespace", ""], "namespace"),
    (["--budget", "0"], "budget"),
    (["--area-size", "-50"], "--area-size"),
    (["--planners", "coma=/nonexistent/policy.pt"], "/nonexistent/policy.pt"),
    (["--planners", "ig,ig"], "planner 'ig' is given twice"),
    (["--config", "{yaml}", "--planners", "ig"], "duplicate key 'n_agents'"),
])
def test_compare_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, argv, message):
    argv = [a.replace("{yaml}", _yaml_file(tmp_path, "team:\n  n_agents: 2\n  n_agents: 4\n"))
            for a in argv]
    out = tmp_path / "out"
    try:
        code = compare_main(argv + ["--out", str(out), "--trials" if "--trials" not in argv
                                    else "--seed", "1" if "--trials" not in argv else "0"])
    except SystemExit as exit_:  # argparse refuses malformed flags itself
        code = exit_.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("text, message", [
    ("team: [1, 2]\n", "team"),
    ("robots: {n: 2}\n", "robots"),
    ("team: {n_agent: 2}\n", "n_agent"),
    ("team: {n_agents: two}\n", "n_agents"),
    ("world: {resolution: 0}\n", "resolution"),
    ("sensor: {altitudes: [5, 10]}\n", "sensor"),
    ("terrain: {kind: mixture, mixture: {split: -1}}\n", "mixture"),
    (": : :\n", "not valid YAML"),
])
def test_bad_config_files_name_the_key_and_the_file(tmp_path, text, message):
    from ipp_toolkit.config.files import load_config

    path = _yaml_file(tmp_path, text)
    with pytest.raises(ValueError, match=message) as error:
        load_config(path)
    assert path in str(error.value)


@pytest.mark.parametrize("call, message", [
    ("EnvConfig().replace(team={'n_agents': 0})", "n_agents"),
    ("EnvConfig().replace(features={'gain_smoothing': float('nan')})", "gain_smoothing"),
    ("evaluate(EnvConfig(), 'ig', missions=0)", "missions"),
    ("evaluate(EnvConfig(), 'ig', seed=-1)", "seed"),
    ("make_planner('ig', overlap_discount=2.0)", "overlap_discount"),
    ("make_planner('ig_spatial', sigma=0.0)", "sigma"),
    ("make_sb3_vec_env(EnvConfig(), n_envs=0, seed=0)", "n_envs"),
    ("make_sb3_vec_env(EnvConfig(), n_envs=1, seed=0, invalid_action='skip')",
     "invalid_action"),
    ("IPPEnv(EnvConfig()).reset(seed=-3)", "seed"),
    ("IPPEnv(EnvConfig()).reset(seed=0, options={'mission': -1})", "mission"),
])
def test_python_api_bad_input_raises_value_error_naming_it(call, message):
    from ipp_toolkit.config.schema import EnvConfig  # noqa: F401 - used by the calls
    from ipp_toolkit.env import IPPEnv  # noqa: F401
    from ipp_toolkit.planning import make_planner  # noqa: F401
    from ipp_toolkit.runs.evaluation import evaluate  # noqa: F401
    from ipp_toolkit.vec import make_sb3_vec_env  # noqa: F401

    with pytest.raises(ValueError, match=message):
        eval(call)


def test_a_raster_with_only_nodata_is_refused(tmp_path):
    import numpy as np

    from ipp_toolkit.config.schema import EnvConfig
    from ipp_toolkit.sim.mission import reset_mission

    path = tmp_path / "empty.npy"
    np.save(path, np.full((64, 64), np.nan))
    config = EnvConfig().replace(world={"resolution": 1.0},
                                 terrain={"kind": "raster", "raster": str(path), "threshold": 1.0})
    with pytest.raises(ValueError, match="empty.npy"):
        reset_mission(config, seed=0, mission=0)


@pytest.mark.slow  # in this process, fast: test_coma's resumed run trains the same weights
def test_a_killed_coma_training_resumes_without_loss_or_duplicates(tmp_path):
    import csv
    import os
    import signal
    import subprocess
    import sys
    import time

    from coma.persistence import load_policy

    out = tmp_path / "run"
    argv = ["coma", "--out", str(out), "--missions", "24", "--agents", "2", "--resolution",
            "1.0", "--no-progress", "--warm-start", "none", "--set", "width=8",
            "--set", "hidden=16", "--set", "missions_per_update=2", "--set", "eval_missions=1",
            "--set", "minibatch_size=60", "--set", "checkpoint_every=1"]
    script = "import sys; from reports.cli import train_main; sys.exit(train_main(sys.argv[1:]))"
    process = subprocess.Popen([sys.executable, "-c", script, *argv], start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        progress = out / "progress.csv"
        if progress.exists() and len(progress.read_text().splitlines()) >= 4:
            break
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    rows_when_killed = len((out / "progress.csv").read_text().splitlines()) - 1
    assert 0 < rows_when_killed < 12  # killed mid-run
    assert train_main(argv + ["--resume"]) == 0
    with open(out / "progress.csv", newline="") as handle:
        updates = [int(row["update"]) for row in csv.DictReader(handle)]
    assert updates == list(range(1, 13))  # every update once, in order
    networks, _ = load_policy(out / "last.pt")
    assert networks is not None and (out / "best.pt").exists()
