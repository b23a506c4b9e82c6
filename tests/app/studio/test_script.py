"""Scripted studio runs without a window: every step is checked before the window opens, and a step that cannot be
done is one line naming it (steps[INDEX] (ACTION)) and the problem; a wait that times out says what it waited for."""

from __future__ import annotations

import json
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from app.errors import UserInputError
from app.studio.script import SPECS, STEPS, Script
from app.studio.script_fields import ScriptError, check_script
from app.studio.session import Display


def problem(*steps) -> str:
    with pytest.raises(ScriptError) as e:
        check_script({"steps": list(steps)}, SPECS)
    return str(e.value)


def test_the_three_mistakes_that_ended_in_tracebacks_name_their_step():
    assert problem({"wait_frames": 1}, {"wait_render": True}) == \
        "steps[1] (wait_render): one of draft, preview or final, not true"
    assert problem({"gaze": [10, 0, 0]}) == \
        "steps[0] (gaze): a list of 2 numbers (yaw, pitch in degrees), not [10, 0, 0]"
    # save_neural before a render is no mistake any more (it waits), but its path must be a path
    assert problem({"save_neural": 3}) == "steps[0] (save_neural): a path (a string), not 3"


@pytest.mark.parametrize(("step", "message"), [
    ({"head": [1, 2]}, "(head): a list of 3 numbers (yaw, pitch, roll in degrees), not [1, 2]"),
    ({"head": [1, "2", 3]}, "(head): a list of 3 numbers"),
    ({"waitrender": "final"}, "(waitrender): no such action (did you mean wait_render?)"),
    ({"expression": "smile_L"}, "(expression): no 'value' (it needs value)"),
    ({"expression": "smile_L", "vaule": 1}, "(expression): unknown field 'vaule' (did you mean value?)"),
    ({"expression": "smile_L", "value": 1, "head": [0, 0, 0]}, "(expression+head): one action a step, not 2"),
    ({"buffer": "rgbb"}, "(buffer): one of rgb, normals,"),
    ({"view": {"yaw": 10}}, "(view): unknown field 'yaw' (did you mean yaw_deg?)"),
    ({"export": {"out": "t.mp4", "size": "64"}},
     "(export): size: a size in pixels (an integer, 16 or more), not \"64\""),
    ({"train": {"out": "x"}}, "(train): no 'dataset' (it needs dataset, out)"),
    ({"wait_frames": -1}, "(wait_frames): a whole number, 0 or more, not -1"),
    ({"wait_job": True, "timeout_s": "10"}, "(wait_job): timeout_s: a number of seconds, 0 or more, not \"10\""),
    ({"reset": "mouth"}, "(reset): a group (expression, head, neck, jaw, gaze, camera, or expression:PART), not"),
    ({"jaw_open_deg": float("nan")}, "(jaw_open_deg): a number, not NaN"),
    ({}, "steps[1] (?): an empty step"),
    ("wait_frames", "steps[1] (?): a step is an object"),
])
def test_a_wrong_step_is_one_line_naming_it(step, message):
    found = problem({"refine_to": "final"}, step)  # the second step is the wrong one
    assert found.startswith("steps[1] (") and message in found and "\n" not in found, found


def test_right_scripts_pass_and_the_file_is_named(tmp_path):
    check_script({"report": "r.json", "steps": [
        {"refine_to": "final"}, {"wait_render": "final", "timeout_s": 60}, {"expression": 0, "value": 0.5},
        {"expression": "smile_L", "value": 1}, {"gaze": [10, -5.5]}, {"view": {"yaw_deg": -20.0}},
        {"export": {"out": "t.mp4", "frames": 12, "sweep_deg": None}}, {"expect_warning": None},
        {"timeline": -1}, {"save_neural": "a.png"}]}, SPECS)
    with pytest.raises(ScriptError, match="not a list"):
        check_script([{"wait_frames": 1}], SPECS)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"steps": [{"gaze": [1, 2, 3]}]}))
    with pytest.raises(UserInputError) as e:  # the command line's one-line error, exit status 2 (app/cli.py)
        Script.load(bad)
    assert str(e.value) == f"{bad}: steps[0] (gaze): a list of 2 numbers (yaw, pitch in degrees), not [1, 2, 3]"
    bad.write_text("{\"steps\": [")
    with pytest.raises(UserInputError, match=f"{bad}: not JSON"):
        Script.load(bad)


def test_every_action_is_checked():
    assert set(SPECS) == set(STEPS)  # test_actions.py holds them to the module's documentation


def fake_studio() -> SimpleNamespace:
    """What save_neural looks at: an avatar open, no render yet (one never comes)."""
    session = SimpleNamespace(avatar=object(), opening=None, display=Display(), dirty=False, errors=[])
    return SimpleNamespace(session=session, worker=SimpleNamespace(result=None, error=""), last_submit_id=1,
                           viewport=SimpleNamespace(neural_image=None, shown=(-1, "", "")))


def run_frames(sc: Script, studio, seconds: float) -> None:
    end = time.perf_counter() + seconds
    while not sc.over and time.perf_counter() < end:
        sc.step(studio)
        time.sleep(0.01)


def test_save_neural_waits_for_a_render_and_times_out_on_one_line(tmp_path):
    studio = fake_studio()
    sc = Script([{"save_neural": str(tmp_path / "n.png"), "timeout_s": 0.2}])
    run_frames(sc, studio, 0.1)
    assert not sc.over and sc.failed == ""  # still waiting: nothing saved, nothing failed
    run_frames(sc, studio, 1.0)
    assert sc.failed == "steps[0] (save_neural): no render on screen after 0.2 s"
    assert not (tmp_path / "n.png").exists()


def test_a_wait_beyond_the_refinement_and_a_missing_avatar_fail_at_once():
    studio = fake_studio()
    studio.session.display.refine_to = "draft"
    sc = Script([{"wait_render": "final"}])
    sc.step(studio)
    assert sc.failed == ("steps[0] (wait_render): waits for the final pass, but the viewport refines only to draft "
                         "(a refine_to step before it sets that)")
    studio.session.avatar = None
    studio.session.errors = ["x: no such avatar folder"]
    sc = Script([{"save_neural": "n.png"}])
    sc.step(studio)
    assert sc.failed == "steps[0] (save_neural): no avatar is open (last message: x: no such avatar folder)"
    studio.session.opening = Path("somewhere")  # while an avatar opens, steps wait for it
    sc = Script([{"save_neural": "n.png"}])
    sc.step(studio)
    assert sc.failed == "" and sc.index == 0
