"""Bad input raises a Python exception carrying the CLI's one-line message."""

import signal
import threading
import _thread

import numpy as np
import pytest

import tendril
from conftest import run_cli


def cli_error(done):
    assert done.returncode != 0
    line = done.stderr.strip().splitlines()[-1]
    assert line.startswith("tendril: error: "), done.stderr
    return line[len("tendril: error: "):]


def test_bad_robot_text_names_the_field(tmp_path, cli):
    text = tendril.Robot.default().toml.replace("radius = 0.0009", "radius = -0.0009")
    with pytest.raises(ValueError, match="backbone.radius"):
        tendril.Robot.from_toml(text)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as raised:
        tendril.Robot.load(path)
    expected = cli_error(run_cli(cli, "fk", "--robot", str(path), "--tensions", "1,0,0,0"))
    assert str(raised.value) == expected


def test_unreadable_robot_file_is_an_oserror(tmp_path):
    with pytest.raises(OSError, match="missing.toml"):
        tendril.Robot.load(tmp_path / "missing.toml")


def test_nan_and_out_of_range_tensions_are_refused_with_the_cli_message(cli):
    robot = tendril.Robot.default()
    for bad, text in [(np.nan, "nan"), (-1.0, "-1"), (11.0, "11")]:
        tensions = np.zeros((3, 4))
        tensions[2, 1] = bad
        with pytest.raises(ValueError) as raised:
            robot.fk(tensions)
        message = cli_error(run_cli(cli, "fk", "--tensions", f"0,{text},0,0"))
        assert str(raised.value) == f"tensions: row 2: {message}"


def test_wrong_shapes_are_refused():
    robot = tendril.Robot.default()
    for bad in [np.zeros((5, 3)), np.zeros(5), np.zeros((2, 2, 4)), 1.0]:
        with pytest.raises(ValueError, match=r"tensions: expected shape \(4,\) or \(n, 4\)"):
            robot.fk(bad)
    with pytest.raises(ValueError, match=r"tip_force: expected shape \(3,\) or \(n, 3\)"):
        robot.fk(np.zeros((2, 4)), tip_force=[1.0, 2.0])
    with pytest.raises(ValueError, match="tip_force: 3 rows for 2 rows"):
        robot.fk(np.zeros((2, 4)), tip_force=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="tip_moment: row 0: my = NaN is not a finite number"):
        robot.fk(np.zeros((2, 4)), tip_moment=[0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="steps"):
        robot.fk(np.zeros(4), steps=0)
    with pytest.raises(ValueError, match="points"):
        robot.shape(np.zeros(4), points=1)
    with pytest.raises(ValueError, match="could not convert string to float"):
        robot.fk([["a", "b", "c", "d"]])


def test_generate_refuses_bad_arguments(tmp_path):
    robot = tendril.Robot.default()
    with pytest.raises(ValueError, match="sampler"):
        tendril.generate(robot, 10, sampler="gaussian")
    with pytest.raises(ValueError, match="--samples must be between 1"):
        tendril.generate(robot, 0)
    with pytest.raises(ValueError, match="is a directory"):
        tendril.generate(robot, 10, path=tmp_path)
    text_robot = tendril.Robot.from_toml(robot.toml)
    with pytest.raises(ValueError, match="made from text"):
        tendril.generate(text_robot, 10, path=tmp_path / "d.csv")
    assert not (tmp_path / "d.csv").exists()


def test_ctrl_c_during_a_long_fk_raises_keyboard_interrupt():
    robot = tendril.Robot.default()
    # Long enough in a release build (~1 s) that the signal arrives mid-call;
    # the batch stops at the next chain of rows, so a dev build waits for one
    # chain (32 rows), not the whole batch.
    tensions = np.random.default_rng(1).uniform(0, 10, (1280, 4))
    # A process started in the background by a non-interactive shell
    # inherits SIGINT ignored, and then interrupt_main() does nothing: give
    # SIGINT Python's own handler for this test, as an interactive session has.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.1, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            robot.fk(tensions, steps=200)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
