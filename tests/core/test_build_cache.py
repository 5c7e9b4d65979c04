"""pipeline.core.build_cache: what a process builds at import, kept on disk under a key of the sources."""

from __future__ import annotations

import numpy as np

from pipeline.core.build_cache import cached, source_key


def test_a_value_is_built_once_then_loaded(tmp_path):
    calls = []

    def build():
        calls.append(1)
        return {"a": np.arange(5.0)}

    first = cached("thing", build, folder=tmp_path, key="k1")
    again = cached("thing", build, folder=tmp_path, key="k1")
    assert len(calls) == 1 and np.array_equal(first["a"], again["a"])
    assert [p.name for p in tmp_path.iterdir()] == ["thing-k1.pickle"]


def test_another_key_builds_anew_and_removes_the_old_file(tmp_path):
    cached("thing", lambda: 1, folder=tmp_path, key="k1")
    assert cached("thing", lambda: 2, folder=tmp_path, key="k2") == 2
    assert [p.name for p in tmp_path.iterdir()] == ["thing-k2.pickle"]


def test_a_damaged_file_is_built_again_and_replaced(tmp_path):
    (tmp_path / "thing-k1.pickle").write_bytes(b"not a pickle")
    assert cached("thing", lambda: [1, 2], folder=tmp_path, key="k1") == [1, 2]
    assert cached("thing", lambda: "never built", folder=tmp_path, key="k1") == [1, 2]


def test_a_folder_that_cannot_be_written_still_gives_the_value(tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("a file where the folder would be")
    assert cached("thing", lambda: 7, folder=blocked / "cache", key="k1") == 7
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_the_key_follows_every_source_byte(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "notes.txt").write_text("not a source")
    key = source_key(tmp_path)
    (tmp_path / "notes.txt").write_text("changed")
    assert source_key(tmp_path) == key
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")
    assert source_key(tmp_path) != key


def test_the_cached_actor_meshes_are_the_built_ones():
    """DEFAULT_MESHES (loaded from the cache when an earlier process wrote it) equals a fresh build."""
    from pipeline.world.actors import DEFAULT_MESHES, ActorMeshes

    fresh = ActorMeshes()
    assert len(DEFAULT_MESHES.models) == len(fresh.models) > 300
    for a, b in zip(DEFAULT_MESHES.models, fresh.models, strict=True):
        assert a.semantic == b.semantic
        for field in ("vertices", "triangles", "material"):
            assert np.array_equal(getattr(a, field), getattr(b, field))
            assert getattr(a, field).dtype == getattr(b, field).dtype
    for field in ("model_class", "model_names", "model_pose"):
        assert getattr(DEFAULT_MESHES, field) == getattr(fresh, field)
    for field in ("model_extent", "model_low"):
        assert all(np.array_equal(x, y) for x, y in zip(getattr(DEFAULT_MESHES, field), getattr(fresh, field),
                                                        strict=True))
    # Every model's hull and corner normals come with them (computed when the cache was written), as built lazily.
    assert len(DEFAULT_MESHES._hulls) == len(DEFAULT_MESHES._corners) == len(fresh.models)
    for model in range(0, len(fresh.models), 7):
        assert np.array_equal(DEFAULT_MESHES.hull_mask(model), fresh.hull_mask(model))
        assert np.array_equal(DEFAULT_MESHES.corner_normals(model), fresh.corner_normals(model))


def test_keep_holds_the_most_recently_used_keys(tmp_path):
    import os

    assert cached("thing", lambda: 1, folder=tmp_path, key="k1", keep=2) == 1
    assert cached("thing", lambda: 2, folder=tmp_path, key="k2", keep=2) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thing-k1.pickle", "thing-k2.pickle"]
    os.utime(tmp_path / "thing-k1.pickle", ns=(10**9, 10**9))
    os.utime(tmp_path / "thing-k2.pickle", ns=(2 * 10**9, 2 * 10**9))
    assert cached("thing", lambda: "never built", folder=tmp_path, key="k1", keep=2) == 1  # a use: k1 newest now
    assert cached("thing", lambda: 3, folder=tmp_path, key="k3", keep=2) == 3  # k2, the least recently used, goes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thing-k1.pickle", "thing-k3.pickle"]
    cached("other", lambda: 0, folder=tmp_path, key="k1")  # another name's files are its own
    assert len(list(tmp_path.iterdir())) == 3


def test_keep_must_be_positive(tmp_path):
    import pytest

    with pytest.raises(ValueError, match="keep must be at least 1"):
        cached("thing", lambda: 1, folder=tmp_path, key="k1", keep=0)
