"""Top-down renders: size and aspect, the grid mapping, trajectory colours and marks, labels, the CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import AdaptenvError
from adaptenv.render import labels
from adaptenv.render import topdown as td
from adaptenv.render.topdown import render_house, render_map, render_to_file
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import load_house
from adaptenv.sim.trajectory import EpisodeMetrics, Pose, Step, Trajectory

runner = CliRunner()


REAL_HOUSE = Path(__file__).resolve().parents[1] / "data" / "procthor-10k-train-1.json"


@pytest.fixture(scope="module")
def house():
    return load_house(REAL_HOUSE, validate=False)


@pytest.fixture(scope="module")
def empty_house(house):
    """The real house's rooms and walls with no objects: nothing covers a drawn path."""
    h = house.model_copy(deep=True)
    h.objects = []
    return h


def kitchen_walk(collide_at: int | None = None) -> Trajectory:
    """Five poses 1 m apart along z = 2.5 in the real house's kitchen (x 8.8..15.8, z 0..5.3)."""
    steps = []
    for i, x in enumerate((10.0, 11.0, 12.0, 13.0)):
        steps.append(Step(pose=Pose(x=x, z=2.5, yaw=0.0), action="m"))
        if i == collide_at:
            steps.append(Step(pose=Pose(x=x + 1.0, z=2.5, yaw=0.0), action="m", moved=False))
    return Trajectory(house="test", target_type="Fridge", target_ids=["Fridge|x"], target_positions=[(12.0, 4.2)],
                      start=Pose(x=10.0, z=2.5, yaw=0.0), steps=steps, final_pose=Pose(x=14.0, z=2.5, yaw=0.0),
                      metrics=EpisodeMetrics(success=False, spl=0.0, sel=0.0, episode_length=len(steps),
                                             path_length=4.0, final_geodesic=1.0, collisions=0, min_clearance=0.3,
                                             rooms_visited=1, first_sight_step=None, optimal_path_length=3.0))


def pixel(img: Image.Image, xy) -> tuple[int, int, int]:
    return img.getpixel((int(round(float(xy[0]))), int(round(float(xy[1])))))


def near_pixels(img: Image.Image, xy, r: int = 1) -> set[tuple[int, int, int]]:
    """Colours within r pixels of a point (Pillow rounds fractional coordinates its own way)."""
    x, y = int(round(float(xy[0]))), int(round(float(xy[1])))
    return {img.getpixel((x + dx, y + dy)) for dx in range(-r, r + 1) for dy in range(-r, r + 1)}


def test_real_house_at_1024_keeps_aspect_and_has_content(house):
    r = render_map(house, size=1024)
    img, t = r.image, r.transform
    assert max(img.size) == 1024 and img.mode == "RGB"
    left, top, right, bottom = t.area
    min_x, min_z, max_x, max_z = SceneGeometry.from_house(house).bounds
    # Uniform scale: the drawing area has the house's aspect ratio to within a pixel.
    assert (right - left) / (bottom - top) == pytest.approx((max_x - min_x) / (max_z - min_z), abs=2e-3)
    assert left >= 0 and top >= 0 and right <= img.size[0] and bottom <= img.size[1]
    colours = set(map(tuple, np.asarray(img).reshape(-1, 3)[::7].tolist()))
    assert len(colours) > 50
    for c in (td.WALL, td.MOVABLE_FILL, td.FIXED_FILL, td.ROOM_FILLS["Kitchen"], td.ROOM_FILLS["Bedroom"]):
        assert c in colours


def test_every_floor_object_is_labelled_once_with_its_full_id(house):
    r = render_map(house, size=1024, grid=True)
    geometry = SceneGeometry.from_house(house)
    ids = sorted(f.object_id for f in geometry.floor_objects)
    assert sorted(lab.text for lab in r.labels) == ids
    outside = [lab.box for lab in r.labels if not lab.inside]
    assert outside, "at 1024 px small objects need outside labels"
    boxes = np.array([lab.box for lab in r.labels])
    ov = labels._overlap(boxes, boxes)
    np.fill_diagonal(ov, 0)
    assert ov.max() == 0, "two id labels overlap"
    w, h = r.image.size
    assert (boxes[:, 0] >= 0).all() and (boxes[:, 2] <= w).all() and (boxes[:, 3] <= h).all()
    assert (boxes[:, 1] >= r.layout.header_bottom).all()
    assert min(lab.size for lab in r.labels) >= 9


def test_grid_maps_world_bounds_to_the_drawing_area_and_z_up(house):
    r = render_map(house, size=1024, grid=True)
    t = r.transform
    min_x, min_z, max_x, max_z = SceneGeometry.from_house(house).bounds
    left, top, right, bottom = t.area
    assert t.point(min_x, min_z) == pytest.approx((left, bottom))
    assert t.point(max_x, max_z) == pytest.approx((right, top))
    # The longer side (z here) spans grid 0..100; grid y grows with world +z, upward in the image.
    assert max_z - min_z > max_x - min_x
    assert tuple(map(float, t.grid_to_px(0, 100))) == pytest.approx((left, top))
    assert t.point(5.0, 6.0)[1] < t.point(5.0, 5.0)[1]
    assert t.point(6.0, 5.0)[0] > t.point(5.0, 5.0)[0]
    wx, wz = t.to_world(*t.point(3.3, 7.7))
    assert (float(wx), float(wz)) == pytest.approx((3.3, 7.7))


def test_tick_marks_are_drawn_where_the_transform_puts_grid_values(house):
    r = render_map(house, size=1024, grid=True, legend=False)
    img, t = r.image, r.transform
    left, top, right, bottom = t.area
    tick = r.layout.font_size * 0.5
    # Left axis: a dark tick at grid y = 0, 50 and 100; none at 2.5 (between ticks).
    col = left - 2 - tick * 0.8
    for gy in (0, 50, 100):
        assert td.TICK in near_pixels(img, (col, t.grid_to_px(0, gy)[1])), gy
    assert near_pixels(img, (col, t.grid_to_px(0, 2.5)[1])) == {td.BACKGROUND}
    # Bottom axis: ticks at grid x = 0 and 90 (the house's right edge is at 90.0 units).
    row = bottom + 2 + tick * 0.8
    gx_max = float(t.grid.meters_to_units(t.size_m[0]))
    assert gx_max == pytest.approx(90.0, abs=0.05)
    for gx in (0, 40, 90):
        assert td.TICK in near_pixels(img, (t.grid_to_px(gx, 0)[0], row)), gx
    assert near_pixels(img, (t.grid_to_px(2.5, 0)[0], row)) == {td.BACKGROUND}


def test_a_mark_at_a_world_point_sits_on_its_grid_ticks(empty_house):
    """A target placed at grid (40, 10) is drawn on the column of the x=40 tick and the row of the y=10 tick."""
    plain = render_map(empty_house, size=1024, grid=True, legend=False)
    t = plain.transform
    x, z = (float(v) for v in t.grid.to_world(40.0, 10.0))
    traj = kitchen_walk().model_copy(update={"target_positions": [(x, z)]})
    r = render_map(empty_house, size=1024, grid=True, legend=False, trajectory=traj)
    img = np.asarray(r.image)
    cx, cy = r.transform.point(x, z)
    assert tuple(img[round(cy), round(cx)]) == td.TARGET
    # Find the tick columns and rows in the margins and check the cross lines up with them.
    tick = r.layout.font_size * 0.5
    left, top, right, bottom = r.transform.area
    row = img[round(bottom + 2 + tick * 0.8)]
    tick_cols = np.flatnonzero((row == td.TICK).all(axis=1))
    col = img[:, round(left - 2 - tick * 0.8)]
    tick_rows = np.flatnonzero((col == td.TICK).all(axis=1))
    assert np.min(np.abs(tick_cols - cx)) <= 1.0
    assert np.min(np.abs(tick_rows - cy)) <= 1.0


def test_trajectory_goes_yellow_to_orange_with_start_end_and_target(empty_house):
    traj = kitchen_walk()
    r = render_map(empty_house, size=1024, trajectory=traj, labels=False)
    img, t = r.image, r.transform
    first = pixel(img, t.point(10.5, 2.5))
    last = pixel(img, t.point(13.5, 2.5))
    assert first[0] > 230 and first[1] > 200 and first[2] < 80, first  # yellow
    assert last[0] > 230 and 80 < last[1] < 150 and last[2] < 80, last  # orange
    assert first == td.PATH_START and last == td.PATH_END
    assert pixel(img, t.point(12.0, 4.2)) == td.TARGET
    assert pixel(img, t.point(10.0, 2.5)) == td.START_FILL
    assert pixel(img, t.point(14.0, 2.5)) == td.END_FILL


def test_collisions_are_red_crosses(empty_house):
    def red_near(traj):
        r = render_map(empty_house, size=1024, trajectory=traj, labels=False, legend=False)
        cx, cy = r.transform.point(12.0, 2.5)
        crop = np.asarray(r.image)[round(cy) - 8:round(cy) + 9, round(cx) - 8:round(cx) + 9]
        return int((crop == td.COLLISION).all(axis=2).sum())

    assert red_near(kitchen_walk(collide_at=1)) > 6
    assert red_near(kitchen_walk()) == 0


def test_caption_needs_room_and_title_shifts_the_map_down(empty_house):
    a = render_map(empty_house, size=800)
    b = render_map(empty_house, size=800, title="hello", trajectory=kitchen_walk())
    assert b.transform.area[1] > a.transform.area[1]
    assert max(b.image.size) == 800


def test_highlight_fills_the_object(house):
    fp = SceneGeometry.from_house(house).footprint("Sofa|3|3")
    plain = render_map(house, size=800, labels=False)
    lit = render_map(house, size=800, labels=False, highlight={"Sofa|3|3": "#00ff00"})
    xs, ys = plain.transform.to_px(fp.corners[:, 0], fp.corners[:, 1])
    box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)

    def green(img):
        return int((np.asarray(img.crop(box)) == (0, 255, 0)).all(axis=2).sum())

    area = (box[2] - box[0]) * (box[3] - box[1])
    assert green(lit.image) > 0.5 * area
    assert green(plain.image) == 0


def test_bad_highlights_and_sizes_are_clear_errors(house):
    with pytest.raises(AdaptenvError, match="no object or door with that id"):
        render_house(house, highlight={"Nope|1": "red"})
    with pytest.raises(AdaptenvError, match="not a colour"):
        render_house(house, highlight={"Sofa|3|3": "not-a-colour"})
    with pytest.raises(AdaptenvError, match="too small"):
        render_house(house, size=100)


def test_no_labels_and_small_sizes_render(house):
    img = render_house(house, size=300, grid=True, labels=False)
    assert max(img.size) == 300


def test_render_to_file_writes_png(house, tmp_path):
    p = render_to_file(house, tmp_path / "sub" / "map.png", size=400)
    with Image.open(p) as img:
        assert img.format == "PNG" and max(img.size) == 400


# ---------------------------------------------------------------- CLI
def test_cli_render_writes_png_with_trajectory(real_house_path, tmp_path):
    in_real_house = {"target_ids": ["Fridge|2|1"], "target_positions": [(15.403, 2.205)]}  # its real fridge
    xs = [10.0 + 0.2 * k for k in range(11)]  # the CLI reads an episode: one 0.2 m move a step, one blocked
    steps = [Step(pose=Pose(x=x, z=2.5, yaw=90.0), action="m") for x in xs[:-1]]
    steps.insert(3, Step(pose=Pose(x=xs[3], z=2.5, yaw=90.0), action="m", moved=False))
    walk = kitchen_walk().model_copy(update={**in_real_house, "start": steps[0].pose, "steps": steps,
                                             "final_pose": Pose(x=xs[-1], z=2.5, yaw=90.0)})
    traj = walk.save(tmp_path / "t.json")
    out = tmp_path / "map.png"
    result = runner.invoke(app, ["render", str(real_house_path), "-o", str(out), "--trajectory", str(traj),
                                 "--grid", "--size", "600", "--highlight", "Sofa|3|3=red"])
    assert result.exit_code == 0, result.output
    assert "wrote" in result.output
    with Image.open(out) as img:
        assert img.format == "PNG" and max(img.size) == 600


def test_cli_missing_house_is_a_clean_error(tmp_path):
    missing = tmp_path / "nope.json"
    result = runner.invoke(app, ["render", str(missing), "-o", str(tmp_path / "m.png")])
    assert result.exit_code == 1
    assert isinstance(result.exception, AdaptenvError)
    assert str(missing) in str(result.exception)
    assert not (tmp_path / "m.png").exists()


def test_cli_broken_trajectory_is_one_line_without_traceback(real_house_path, tmp_path):
    bad = tmp_path / "t.json"
    bad.write_text(json.dumps({"house": "x"}))
    proc = subprocess.run([sys.executable, "-c", "from adaptenv.cli import main; main()", "render",
                           str(real_house_path), "-o", str(tmp_path / "m.png"), "--trajectory", str(bad)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    err = proc.stderr.strip()
    assert err.startswith("error:") and str(bad) in err.replace("\n", "")
    assert "Traceback" not in proc.stdout + proc.stderr


@pytest.mark.parametrize(("asset_id", "leaves"), [("Doorframe_Double_5", 0), ("Doorway_10", 1), ("Doorway_Double_1", 2)])
def test_doors_are_drawn_with_their_leaves(asset_id, leaves):
    """A doorframe has no leaf, a door one from its first jamb, a double door one from each jamb."""
    from tests.sim import helpers as H

    h = H.two_rooms(1.2)
    h.doors[0].assetId = asset_id
    assert td.door_leaves(asset_id) == leaves
    r = render_map(h, size=600)
    # The door spans z 1.4..2.6 on the wall x = 4; leaves swing into room 0 (x < 4), 0.25 m from each jamb.
    at_first = near_pixels(r.image, r.transform.to_px(3.75, 1.4), 2)
    at_second = near_pixels(r.image, r.transform.to_px(3.75, 2.6), 2)
    assert (td.DOOR in at_first) == (leaves >= 1)
    assert (td.DOOR in at_second) == (leaves == 2)


def tall_fridge_walk() -> tuple:
    """A tall, narrow room (2 m x 12 m) with a fridge at (1, 10), and a failed episode whose target is that fridge."""
    from tests.sim import helpers as H

    house = H.one_room(size=(2.0, 12.0), objects=[H.Obj(H.TALL_TARGET, 1.0, 10.0)])
    steps = [Step(pose=Pose(x=1.0, z=1.0 + i, yaw=0.0), action="m") for i in range(5)]
    traj = Trajectory(house="tall", target_type="Fridge", target_ids=[house.objects[0].id],
                      target_positions=[(1.0, 10.0)], start=Pose(x=1.0, z=1.0, yaw=0.0), steps=steps,
                      final_pose=Pose(x=1.0, z=6.0, yaw=0.0), policy="pretrained",
                      metrics=EpisodeMetrics(success=False, spl=0.0, sel=0.0, episode_length=5, path_length=4.0,
                                             final_geodesic=4.0, collisions=12, min_clearance=0.3, rooms_visited=1,
                                             first_sight_step=None, optimal_path_length=9.0))
    return house, traj


def test_tall_narrow_house_keeps_the_whole_header_and_legend():
    """The panel is widened (map centred) so the caption fits at its font size and no legend text is cut."""
    from PIL import ImageDraw

    from adaptenv.render.text import get_font

    house, traj = tall_fridge_walk()
    size = 1024
    r = render_map(house, trajectory=traj, grid=True, size=size, title="house_07: a tall, narrow house")
    width = r.image.size[0]
    assert width >= td.MIN_WIDTH_FRACTION * size
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    fs = r.layout.font_size
    caption = "".join(text for text, _ in td._caption_parts(traj))
    assert "SPL 0.00" in caption
    assert measure.textbbox((r.layout.text_left, 0), caption, font=get_font(fs))[2] <= width - r.layout.text_left
    small = max(9, fs - 2)
    for row in r.layout.legend_rows:  # the positions _draw_legend writes each item's text at
        x = min(r.transform.area[0], fs * 0.8)
        for item in row:
            text_x = x if item == td._GRID_NOTE else x + small * 1.6
            bold = item == td._GRID_NOTE
            assert measure.textbbox((text_x, 0), item, font=get_font(small, bold), anchor="lm")[2] <= width, item
            x += td._legend_item_width(item, small)
    assert {item for row in r.layout.legend_rows for item in row} >= {"window", "collision", "target"}


def test_the_targets_label_stays_off_its_cross():
    house, traj = tall_fridge_walk()
    fridge = house.objects[0].id
    plain = render_map(house, size=1024)
    assert next(lab for lab in plain.labels if lab.text == fridge).inside  # without the cross: on the fridge
    r = render_map(house, trajectory=traj, size=1024)
    box = next(lab.box for lab in r.labels if lab.text == fridge)
    cx, cy = r.transform.point(1.0, 10.0)
    arm = td._PixelScene.of(SceneGeometry.from_house(house), r.transform).cross_arm
    cross = np.array([[cx - arm, cy - arm, cx + arm, cy + arm]])
    assert labels._overlap(np.array([box]), cross)[0, 0] == 0


def test_a_highlighted_door_is_drawn_on_a_band_of_its_colour(house):
    door = next(d for d in house.doors if d.room0 != d.room1)

    def green(img) -> int:
        return int((np.asarray(img.convert("RGB")) == (0, 255, 0)).all(axis=2).sum())

    assert green(render_house(house, highlight={door.id: "#00ff00"})) > 20
    assert green(render_house(house)) == 0
