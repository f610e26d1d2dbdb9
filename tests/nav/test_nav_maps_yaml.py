"""map_server YAML + PGM/PNG loading and saving, following map_server's pixel rules."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from emos.actors.nav.data import ROOMS_MAP_YAML
from emos.actors.nav.maps import MapFileError, OccupancyGridMap, load_map, read_pgm, save_map, write_pgm

pytestmark = pytest.mark.unit


def write_map(tmp_path: Path, pixels: np.ndarray, name: str = "m", **keys) -> Path:
    write_pgm(tmp_path / f"{name}.pgm", pixels)
    doc = {
        "image": f"{name}.pgm",
        "resolution": 0.1,
        "origin": [1.0, -2.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    doc.update(keys)
    doc = {k: v for k, v in doc.items() if v is not None}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def random_trinary(rng, shape=(23, 31)) -> np.ndarray:
    return rng.choice(np.array([-1, 0, 100], np.int8), size=shape, p=[0.2, 0.6, 0.2])


def test_first_image_row_is_the_top_of_the_map(tmp_path):
    pixels = np.full((4, 3), 254)
    pixels[0, 0] = 0  # top-left pixel: occupied
    grid = load_map(write_map(tmp_path, pixels))
    assert grid.width == 3 and grid.height == 4
    assert grid.data[3, 0] == 100  # top row of the image = highest y = last grid row
    assert (grid.data != 100).sum() == 11
    # World position of that cell: origin + (0.5, 3.5) cells.
    assert grid.values_at(np.array([1.05, -2.0 + 0.35]))[()] == 100
    assert grid.values_at(np.array([1.05, -2.0 + 0.05]))[()] == 0


def test_trinary_thresholds_exactly_as_map_server(tmp_path):
    # occ = 1 - p/255; occupied if occ > 0.65, free if occ < 0.196, else unknown.
    pixels = np.array([[0, 89, 90, 100, 204, 205, 206, 254, 255]])
    grid = load_map(write_map(tmp_path, pixels))
    occ = 1 - pixels[0] / 255.0
    want = np.where(occ > 0.65, 100, np.where(occ < 0.196, 0, -1))
    assert grid.data[0].tolist() == want.tolist()
    assert grid.data[0].tolist() == [100, 100, -1, -1, -1, -1, 0, 0, 0]


def test_negate_inverts_shades(tmp_path):
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, size=(12, 9))
    plain = load_map(write_map(tmp_path, pixels, "a"))
    negated = load_map(write_map(tmp_path, 255 - pixels, "b", negate=1))
    assert np.array_equal(plain.data, negated.data)


def test_scale_and_raw_modes(tmp_path):
    pixels = np.array([[255, 230, 200, 150, 100, 50, 0]])
    scale = load_map(write_map(tmp_path, pixels, "s", mode="scale", free_thresh=0.1, occupied_thresh=0.9))
    occ = 1 - pixels[0] / 255.0
    want = np.where(occ > 0.9, 100, np.where(occ < 0.1, 0, np.rint((occ - 0.1) / 0.8 * 100)))
    assert scale.data[0].tolist() == want.astype(int).tolist()
    raw = load_map(write_map(tmp_path, np.array([[0, 7, 100, 101, 255]]), "r", mode="raw"))
    assert raw.data[0].tolist() == [0, 7, 100, -1, -1]


@pytest.mark.parametrize("mode", ["trinary", "raw"])
def test_save_load_round_trip_is_exact(tmp_path, mode):
    rng = np.random.default_rng(1)
    data = random_trinary(rng) if mode == "trinary" else rng.integers(-1, 101, size=(17, 13)).astype(np.int8)
    grid = OccupancyGridMap(data=data, resolution=0.05, origin=(-3.5, 2.25, 0.1))
    path = save_map(grid, tmp_path / "out" / "saved.yaml", mode=mode)
    back = load_map(path)
    assert np.array_equal(back.data, grid.data)
    assert back.resolution == grid.resolution and back.origin == pytest.approx(grid.origin)
    # And once more: save(load(x)) == x on disk too.
    path2 = save_map(back, tmp_path / "again.yaml", mode=mode)
    assert (tmp_path / "again.pgm").read_bytes().split(b"\n", 2)[2] == (tmp_path / "out" / "saved.pgm").read_bytes().split(b"\n", 2)[2]
    assert load_map(path2).data.tolist() == grid.data.tolist()


def test_scale_round_trip_keeps_known_values(tmp_path):
    data = np.arange(0, 101, dtype=np.int8).reshape(1, -1)
    back = load_map(save_map(OccupancyGridMap(data=data, resolution=0.1), tmp_path / "s.yaml", mode="scale"))
    assert back.data.tolist() == data.tolist()


def test_save_rejects_thresholds_that_lose_unknown_cells(tmp_path):
    grid = OccupancyGridMap(data=np.array([[-1, 0, 100]], np.int8), resolution=0.1)
    with pytest.raises(ValueError, match="free_thresh"):
        save_map(grid, tmp_path / "x.yaml", free_thresh=0.25)


def test_png_colour_and_alpha_follow_map_server(tmp_path):
    Image = pytest.importorskip("PIL.Image", reason="Pillow (emos[sim]) provides PNG support")
    rgb = np.zeros((2, 3, 3), np.uint8)
    rgb[0, 0] = (255, 255, 255)     # white -> free
    rgb[0, 1] = (255, 0, 0)         # mean 85 -> occ 0.667 -> occupied
    rgb[0, 2] = (200, 210, 220)     # mean 210 -> occ 0.176 -> free
    rgb[1, :] = (205, 205, 205)     # unknown grey
    Image.fromarray(rgb, "RGB").save(tmp_path / "c.png")
    grid = load_map(write_map(tmp_path, np.zeros((1, 1)), "c", image="c.png"))
    assert grid.data[1].tolist() == [0, 100, 0]
    assert grid.data[0].tolist() == [-1, -1, -1]
    # Trinary mode averages alpha (255 = opaque) in with the colours.
    rgba = np.zeros((1, 2, 4), np.uint8)
    rgba[0, 0] = (255, 255, 255, 255)
    rgba[0, 1] = (255, 255, 255, 0)   # mean(255, 255, 255, 0) / 255 = .75 -> occ .25 -> unknown
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    grid = load_map(write_map(tmp_path, np.zeros((1, 1)), "a", image="a.png"))
    assert grid.data[0].tolist() == [0, -1]
    # Scale mode: any non-opaque pixel is unknown.
    grid = load_map(write_map(tmp_path, np.zeros((1, 1)), "a2", image="a.png", mode="scale"))
    assert grid.data[0].tolist() == [0, -1]


def test_ascii_p2_and_16bit_pgm(tmp_path):
    (tmp_path / "p2.pgm").write_text("P2\n# a comment\n3 2\n# another\n15\n0 15 7\n15 15 0\n")
    pixels, maxval = read_pgm(tmp_path / "p2.pgm")
    assert maxval == 15 and pixels.tolist() == [[0, 15, 7], [15, 15, 0]]
    grid = load_map(write_map(tmp_path, np.zeros((1, 1)), "yaml_p2", image="p2.pgm"))
    assert grid.data.tolist() == [[0, 0, 100], [100, 0, -1]]
    raster = np.array([[0, 65535]], dtype=">u2").tobytes()
    (tmp_path / "w.pgm").write_bytes(b"P5 2 1 65535\n" + raster)
    assert read_pgm(tmp_path / "w.pgm")[0].tolist() == [[0, 65535]]


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "free_thresh", "occupied_thresh", "negate"])
def test_missing_key_names_key_and_file(tmp_path, key):
    path = write_map(tmp_path, np.zeros((2, 2)), **{key: None})
    with pytest.raises(MapFileError) as err:
        load_map(path)
    assert repr(key) in str(err.value) and str(path) in str(err.value)


@pytest.mark.parametrize(
    "keys, message",
    [
        ({"free_thresh": 0.7}, "lower than 'occupied_thresh'"),
        ({"occupied_thresh": 1.5}, "'occupied_thresh' must be in"),
        ({"free_thresh": -0.1}, "'free_thresh' must be in"),
        ({"resolution": 0}, "'resolution' must be > 0"),
        ({"resolution": "fine"}, "'resolution' must be a number"),
        ({"origin": [0, 0]}, "'origin' must be a list"),
        ({"mode": "fancy"}, "'mode' must be one of"),
        ({"negate": 2}, "'negate' must be"),
    ],
)
def test_bad_values_are_clear_errors(tmp_path, keys, message):
    with pytest.raises(MapFileError, match=message):
        load_map(write_map(tmp_path, np.zeros((2, 2)), **keys))


def test_unreadable_images_and_yaml(tmp_path):
    with pytest.raises(MapFileError, match="not found"):
        load_map(write_map(tmp_path, np.zeros((2, 2)), image="missing.pgm"))
    (tmp_path / "trunc.pgm").write_bytes(b"P5\n10 10\n255\n" + bytes(20))
    with pytest.raises(MapFileError, match="truncated"):
        load_map(write_map(tmp_path, np.zeros((2, 2)), "t", image="trunc.pgm"))
    (tmp_path / "junk.pgm").write_bytes(b"hello, not an image")
    with pytest.raises(MapFileError, match="junk.pgm"):
        load_map(write_map(tmp_path, np.zeros((2, 2)), "j", image="junk.pgm"))
    (tmp_path / "bad.yaml").write_text("image: [unclosed\n")
    with pytest.raises(MapFileError, match="invalid YAML"):
        load_map(tmp_path / "bad.yaml")
    with pytest.raises(MapFileError, match="cannot read map file"):
        load_map(tmp_path / "nope.yaml")


def test_shipped_rooms_map():
    grid = load_map(ROOMS_MAP_YAML)
    assert (grid.width, grid.height, grid.resolution) == (200, 200, 0.05)
    assert grid.origin == (-5.0, -5.0, 0.0)
    values = set(np.unique(grid.data).tolist())
    assert values == {-1, 0, 100}
    # Wall between the west rooms at y = 0 with its doorway at x in [-4, -3].
    assert grid.values_at(np.array([-2.0, 0.0]))[()] == 100
    assert grid.values_at(np.array([-3.5, 0.0]))[()] == 0
