"""Run files are written atomically and are ordinary readable files."""

from __future__ import annotations

import json
import stat

import pytest

from adaptenv.curriculum.records import (
    ITERATIONS,
    GalleryItem,
    SceneStore,
    atomic_write_text,
    read_iterations,
)
from adaptenv.errors import ConfigError


def test_atomic_write_replaces_whole_files_readable_by_others(tmp_path):
    path = atomic_write_text(tmp_path / "sub" / "a.txt", "one")
    atomic_write_text(path, "two")
    assert path.read_text() == "two"
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [p.name for p in path.parent.iterdir()] == ["a.txt"]  # no temporary file left behind


@pytest.mark.parametrize("field,value", [("scene", "../../victim"), ("scene", "/tmp/victim"),
                                          ("before_png", "../../elsewhere.png"), ("after_house_json", "/etc/passwd"),
                                          ("edits_json", "iter_0001/../../x.json")])
def test_an_iteration_log_naming_a_file_outside_the_run_is_refused(tmp_path, field, value):
    item = {"scene": "house_00", field: value}
    record = {"iteration": 0, "env_steps": 0, "grad_updates": 0, "edits": 0, "gallery": [item]}
    (tmp_path / ITERATIONS).write_text(json.dumps(record) + "\n")
    with pytest.raises(ConfigError) as err:
        read_iterations(tmp_path)
    line = str(err.value)
    assert line.startswith(f"{tmp_path / ITERATIONS}: line 1") and repr(value) in line and "\n" not in line
    assert GalleryItem(scene="house_00~t01a00", before_png="iter_0001/gallery/a/before.png").scene  # the loop's own


def test_a_scene_store_reads_and_writes_only_inside_its_folder(tmp_path):
    (tmp_path / "victim.json").write_text("{}")
    store = SceneStore(tmp_path / "run" / "scenes")
    with pytest.raises(ConfigError, match="level id '../../victim'"):
        store.house("../../victim")
