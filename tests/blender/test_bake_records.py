"""The bake record kept on an object (an ID property) holds what a 2048^2 bake reports."""


def test_a_record_keeps_sizes_over_two_gigabytes(fresh_scene):
    """ID properties hold 32-bit integers: the first 2048^2 bake (T of 3.2 GB) ended in an
    OverflowError while recording its bytes, after the bake. Larger integers are kept as floats,
    exact; small ones stay integers."""
    import bpy

    from relightable_textures.operators.base.blend_files import object_bakes, record_kind

    mesh = bpy.data.meshes.new("m")
    obj = bpy.data.objects.new("o", mesh)
    fresh_scene.collection.objects.link(obj)
    big = 3_435_973_837 + 2 ** 33
    record_kind(obj, "transport_texture", "/tmp/r.json",
                {"bytes": big, "resolution": 2048, "negative": -(2 ** 40), "ok": True})
    (rec,) = object_bakes(obj)
    assert rec["bytes"] == big and isinstance(rec["bytes"], float)
    assert rec["negative"] == -(2 ** 40)
    assert rec["resolution"] == 2048 and isinstance(rec["resolution"], int)
    assert rec["ok"] in (True, 1)
