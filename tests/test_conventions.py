"""Small conventions across the tools: defaults of the SB3 view, final infos, state() inside
its space, progress lines and task metrics of SB3 runs, --help and --version of every
command."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_config

from ipp_toolkit import __version__
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.vec import make_sb3_vec_env
from reports.cli import compare_main, simulate_main, study_main, train_main


def test_sb3_view_needs_only_a_config_and_reports_the_missions_last_infos():
    config = small_config(n_agents=2, resolution=1.0)
    vec = make_sb3_vec_env(config, render_mode="rgb_array")
    try:
        assert vec.num_envs == 2 and vec.render_mode == "rgb_array"
        vec.reset()
        assert vec.render().ndim == 3
        for _ in range(config.team.budget):
            _, _, dones, infos = vec.step(vec.action_masks().argmax(1))
        assert dones.all()
        # The last step's own infos, not the next mission's reset (SuperSuit overwrites them).
        assert all(info["step"] == config.team.budget for info in infos)
        assert all("terminal_info" not in info for info in infos)
        assert infos[0]["entropy"] < 0.98
    finally:
        vec.close()


def test_state_stays_inside_state_space(monkeypatch):
    import ipp_toolkit.env as env_module

    env = IPPEnv(small_config(n_agents=2))
    env.reset(seed=0)
    planes = env_module.global_state(env.mission, env.config.features)
    planes[3, 0, 0] = -6e-10  # what float rounding gives the entropy plane now and then
    monkeypatch.setattr(env_module, "global_state", lambda *_: planes.copy())
    state = env.state()
    assert env.state_space.contains(state) and state[3, 0, 0] == 0.0


def test_sb3_runs_print_progress_lines_off_a_terminal_and_log_task_metrics(tmp_path, capsys):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = tmp_path / "ppo"
    assert train_main(["ppo", "--timesteps", "128", "--n-envs", "1", "--agents", "2",
                       "--resolution", "1", "--width", "8", "--features-dim", "16",
                       "--hidden", "16", "--n-steps", "32", "--batch-size", "64",
                       "--out", str(out)]) == 0
    err = capsys.readouterr().err
    # pytest's stderr is no terminal: short lines, no tqdm redraws.
    assert "\r" not in err and "100% (128/128 steps" in err
    events = EventAccumulator(str(next((out / "tb").iterdir())))
    events.Reload()
    tags = events.Tags()["scalars"]
    assert "rollout/final_entropy" in tags and "rollout/final_f1" in tags
    entropy = events.Scalars("rollout/final_entropy")[-1].value
    assert 0 < entropy < 1


COMMANDS = [(simulate_main, []), (compare_main, []), (study_main, []), (train_main, []),
            (train_main, ["coma"]), (train_main, ["ppo"]), (train_main, ["sb3"]),
            (train_main, ["sb3", "--algo", "dqn"])]


@pytest.mark.parametrize("main, prefix", COMMANDS)
def test_every_command_has_version_and_help_without_none_defaults(main, prefix, capsys):
    def run(flag: str) -> tuple[int, str]:
        try:
            code = main([*prefix, flag])
        except SystemExit as exit_:
            code = exit_.code
        return code, capsys.readouterr().out

    code, text = run("--version")
    assert code == 0 and text.strip().endswith(__version__)
    code, text = run("--help")
    assert code == 0 and "default: None" not in text
    if main is compare_main or prefix in (["ppo"], ["sb3", "--algo", "dqn"]):
        assert "(default: " in text  # the defaults are shown


def test_the_native_env_keeps_masks_with_action_space_sample():
    env = IPPEnv(small_config(n_agents=2))
    obs, _ = env.reset(seed=1)
    while env.agents:
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
        assert all(o["action_mask"].shape == (6,) for o in obs.values())
    assert np.isfinite(env.state()).all()
