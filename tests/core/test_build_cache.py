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
