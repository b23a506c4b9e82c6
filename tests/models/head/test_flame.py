"""FLAME: our loader and skinning against the smplx package's FLAME layer, on FLAME-format files the
tests write (both the 2020 chumpy layout and the 2023 numpy layout), and the restricted unpickler."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from models.head.controls import Controls
from models.head.flame import load_flame
from models.head.head import Head
from models.head.model import HeadModelError
from tests.models.head.flame_files import (
    CommandRunningObject,
    flame_arrays,
    write_flame_2020,
    write_flame_2023,
)


@pytest.fixture(scope="module")
def flame_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flame")
    arrays = flame_arrays(seed=3)
    write_flame_2023(folder, arrays)
    write_flame_2020(folder, arrays)
    return folder


@pytest.fixture(scope="module")
def smplx_flame(flame_dir):
    smplx = pytest.importorskip("smplx")
    return smplx.FLAME(model_path=str(flame_dir), num_betas=300, num_expression_coeffs=100, batch_size=1,
                       use_face_contour=False, dtype=torch.float64)


def random_controls(rng: np.random.Generator, scale: float = 0.4) -> dict[str, np.ndarray]:
    return {"shape": rng.normal(0, 1, 300), "expression": rng.normal(0, 1, 100),
            **{k: rng.normal(0, scale, 3) for k in ("root", "neck", "jaw", "gaze_left", "gaze_right")}}


ROTATION_CASES = {
    "random": None,
    "zero": np.zeros(3),
    "tiny": np.array([1e-7, -2e-7, 5e-8]),
    "pi_x": np.array([np.pi, 0.0, 0.0]),
    "pi_oblique": np.pi * np.array([1.0, 2.0, -2.0]) / 3.0,
}


@pytest.mark.parametrize("case", ROTATION_CASES)
@pytest.mark.parametrize("layout", ["FLAME_NEUTRAL.pkl", "generic_model.pkl"])
def test_matches_smplx_flame(flame_dir, smplx_flame, case, layout):
    """Posed vertices and landmarks agree with smplx within 1e-5 m for random controls, with every joint
    rotation replaced by the case (0, 1e-7 rad, exactly pi)."""
    rng = np.random.default_rng(hash(case) % 2**32)
    c = random_controls(rng)
    if ROTATION_CASES[case] is not None:
        for k in ("root", "neck", "jaw", "gaze_left", "gaze_right"):
            c[k] = ROTATION_CASES[case]
    ours = Head(load_flame(flame_dir / layout), dtype=torch.float64)
    controls = Controls(**{k: np.asarray(v, np.float64) for k, v in c.items()})
    v, _, lmk = ours(**{k: t.double() for k, t in ours.batch([controls]).items()})
    t = lambda a: torch.as_tensor(a, dtype=torch.float64)[None]
    out = smplx_flame(betas=t(c["shape"]), expression=t(c["expression"]), global_orient=t(c["root"]),
                      neck_pose=t(c["neck"]), jaw_pose=t(c["jaw"]),
                      leye_pose=t(c["gaze_left"]), reye_pose=t(c["gaze_right"]), transl=t(np.zeros(3)))
    torch.testing.assert_close(v, out.vertices.detach(), atol=1e-5, rtol=0)
    torch.testing.assert_close(lmk, out.joints[:, 5:].detach(), atol=1e-5, rtol=0)


def test_2020_and_2023_layouts_give_the_same_model(flame_dir):
    a, b = load_flame(flame_dir / "generic_model.pkl"), load_flame(flame_dir / "FLAME_NEUTRAL.pkl")
    for key in ("template", "shape_basis", "expr_basis", "pose_basis", "J_regressor", "weights"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    assert a.num_shape == 300 and a.num_expression == 100 and a.num_joints == 5
    assert a.joint_names == ("root", "neck", "jaw", "eye_l", "eye_r")


def test_pickle_that_would_run_a_command_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    bad = tmp_path / "generic_model.pkl"
    bad.write_bytes(pickle.dumps({"v_template": CommandRunningObject(marker)}, protocol=2))
    with pytest.raises(HeadModelError, match=r"generic_model\.pkl: unsafe pickle.*(posix|os)\.system"):
        load_flame(bad)
    assert not marker.exists()


@pytest.mark.parametrize("bad_class", [("builtins", "eval"), ("numpy", "load"), ("subprocess", "Popen"),
                                       ("copyreg", "_reconstructor")])
def test_refuses_globals_outside_the_table(tmp_path, bad_class):
    """A hand-written protocol-0 pickle naming a global: refused before it is called."""
    module, name = bad_class
    data = f"c{module}\n{name}\n(S'1+1'\ntR.".encode()
    path = tmp_path / "x.pkl"
    path.write_bytes(data)
    with pytest.raises(HeadModelError, match=r"x\.pkl"):
        load_flame(path)


def test_reconstructor_only_builds_stand_ins():
    """copyreg._reconstructor is allowed, but only for the chumpy and sparse stand-ins."""
    from models.head.safe_pickle import UnsafePickleError, restricted_load

    payload = b"ccopy_reg\n_reconstructor\n(c__builtin__\nset\nc__builtin__\nobject\nNtR."
    with pytest.raises(UnsafePickleError, match="_reconstructor"):
        restricted_load(payload)


@pytest.mark.parametrize(("key", "bad", "message"), [
    ("shapedirs", np.zeros((600, 3, 50)), "shapedirs"),
    ("weights", np.zeros((600, 4)), "weights"),
    ("posedirs", np.zeros((600, 3, 30)), "posedirs"),
    ("kintree_table", np.zeros((2, 3), np.int64), "kintree_table"),
    ("v_template", np.zeros((600, 2)), "v_template"),
])
def test_wrong_shapes_name_the_field(tmp_path, key, bad, message):
    arrays = flame_arrays()
    arrays[key] = bad
    path = write_flame_2023(tmp_path, arrays)
    with pytest.raises(HeadModelError, match=rf"FLAME_NEUTRAL\.pkl: FLAME field '{message}'"):
        load_flame(path)


def test_truncated_pickle(tmp_path):
    path = write_flame_2023(tmp_path, flame_arrays())
    path.write_bytes(path.read_bytes()[:5000])
    with pytest.raises(HeadModelError, match="not a readable FLAME pickle"):
        load_flame(path)


@pytest.mark.parametrize("protocol", [2, 4])
def test_empty_faces_and_embedding_are_clear_errors(tmp_path, protocol):
    """A FLAME file with an empty face array (protocol 2 writes its empty data as bytes(), which the restricted
    unpickler allows with no arguments) and an empty landmark embedding: one clear error each."""
    arrays = flame_arrays()
    arrays["f"] = np.zeros((0, 3), np.int64)
    path = tmp_path / "FLAME_NEUTRAL.pkl"
    path.write_bytes(pickle.dumps(arrays, protocol=protocol))
    with pytest.raises(HeadModelError, match=r"FLAME field 'f' must be \(F,3\) indices"):
        load_flame(path)
    good = write_flame_2023(tmp_path, flame_arrays())
    (tmp_path / "flame_static_embedding.pkl").write_bytes(pickle.dumps(
        {"lmk_face_idx": np.zeros(0, np.int64), "lmk_b_coords": np.zeros((0, 3))}, protocol=protocol))
    with pytest.raises(HeadModelError, match="landmark embedding does not fit"):
        load_flame(good)
