"""Output file stems from object names (issue 59): ``a/b`` and ``a_b`` both became ``a_b`` and
the second bake overwrote the first. :func:`object_stem` is injective over names whose stem
changed; plain names keep the stem they always had (old bakes keep their file names)."""

import os
import subprocess
import sys

import pytest

from relightable_textures.lt_addon.io.names import StemCollision, check_stems, object_stem

TRICKY = ["a/b", "a_b", "a\\b", "a b", "a.b", "a:b", "a*b", "a?b", "a+b", "a_b-000000",
          "My Box", "My_Box", "Cube", "Cube.001", "Cube_001", "Café", "Cafe\u0301", "日本",
          "..", ".", "con", "a" * 63, "a" * 62 + "/", "", "-", "_", "x-abcdef"]


def test_plain_names_keep_their_stem():
    for name in ("Cube", "My_Box", "Cube_001", "Statue", "Café", "日本", "floor-2"):
        assert object_stem(name) == name


def test_stems_are_injective_and_file_safe():
    stems = [object_stem(n) for n in TRICKY]
    assert len(set(stems)) == len(TRICKY), stems
    for s in stems:
        assert s and all(ch.isalnum() or ch in "-_" for ch in s), s
    assert object_stem("a/b") != object_stem("a_b") == "a_b"
    assert object_stem("My Box").startswith("My_Box-") and len(object_stem("My Box")) == 13


def test_a_plain_name_never_takes_the_form_of_a_hashed_one():
    # a user's "a_b-<the hash of a/b>" must not reuse a/b's files
    h = object_stem("a/b")
    assert object_stem(h) != h


def test_stems_are_stable_across_runs():
    code = ("from relightable_textures.lt_addon.io.names import object_stem; "
            f"print([object_stem(n) for n in {TRICKY!r}])")
    outs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True,
                           env={**os.environ, "PYTHONHASHSEED": seed}).stdout
            for seed in ("1", "2")}
    assert len(outs) == 1
    assert eval(outs.pop()) == [object_stem(n) for n in TRICKY]


def test_objects_whose_stems_fold_to_one_file_are_refused():
    check_stems(["a/b", "a_b", "Cube"])   # distinct: fine
    with pytest.raises(StemCollision, match="'Box' and 'box'"):
        check_stems(["Box", "Cube", "box"])
