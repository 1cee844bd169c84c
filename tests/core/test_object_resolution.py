"""Per-object texture sides of a transport bake: NAME=SIDE parsing and the grouping."""

import pytest

from relightable_textures.lt_addon.transport import object_resolution as orr


def test_parse_takes_the_last_equals_sign_and_checks_the_side():
    assert orr.parse("Ground=2048") == ("Ground", 2048)
    assert orr.parse("a=b=64") == ("a=b", 64)
    for bad, words in (("Ground", "NAME=SIDE"), ("=64", "NAME=SIDE"),
                       ("Ground=1k", "whole number"), ("Ground=2", "4..8192"),
                       ("Ground=9000", "4..8192")):
        with pytest.raises(orr.ResolutionError, match=words):
            orr.parse(bad)


def test_groups_by_side_largest_first_in_the_given_order():
    names = ["Statue", "Ground", "Rock", "Tree"]
    assert orr.groups(names, 256, None) == [(256, [0, 1, 2, 3])]
    assert orr.groups(names, 256, {"Ground": 1024, "Tree": 0, "Rock": 128}) == [
        (1024, [1]), (256, [0, 3]), (128, [2])]
    # a side equal to the default joins the default group
    assert orr.groups(names, 256, {"Ground": 256}) == [(256, [0, 1, 2, 3])]


def test_a_name_that_is_not_baked_is_refused_with_the_baked_names():
    with pytest.raises(orr.ResolutionError, match="Grond, which is not baked .baked: Statue, "
                                                  "Ground"):
        orr.groups(["Statue", "Ground"], 256, {"Grond": 1024})
    with pytest.raises(orr.ResolutionError, match="resolution of Ground"):
        orr.groups(["Ground"], 256, {"Ground": 3})
