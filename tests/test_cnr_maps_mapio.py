"""map_server semantics of cnr_sim's map loader (no master)."""
import numpy as np
import pytest
from PIL import Image

from cnr_params import ConfigError
from cnr_maps.mapio import load_map, pixels_to_occupancy


def write_map(tmp_path, pixels, yaml_text=None, name='m', fmt='pgm', **keys):
    img = Image.fromarray(np.asarray(pixels, dtype=np.uint8))
    img.save(tmp_path / f'{name}.{fmt}')
    fields = dict(image=f'{name}.{fmt}', resolution=0.1, origin='[1.0, 2.0, 0.0]', negate=0,
                  occupied_thresh=0.65, free_thresh=0.196)
    fields.update(keys)
    text = yaml_text if yaml_text is not None else ''.join(f'{k}: {v}\n' for k, v in fields.items() if v is not None)
    path = tmp_path / f'{name}.yaml'
    path.write_text(text)
    return str(path)


def test_trinary_thresholds_and_flip(tmp_path):
    # row 0 of the image (top) is black = occupied; bottom row white = free; middle grey = unknown
    px = np.array([[0, 0], [205, 205], [254, 254]])
    m = load_map(write_map(tmp_path, px))
    assert m.data.shape == (3, 2)
    assert m.data[0].tolist() == [0, 0]          # grid row 0 = bottom of the image
    assert m.data[1].tolist() == [-1, -1]
    assert m.data[2].tolist() == [100, 100]
    assert m.resolution == pytest.approx(0.1) and m.origin[:2] == (1.0, 2.0)
    assert m.world_to_cell(1.05, 2.25) == (2, 0)


def test_threshold_comparisons_are_strict():
    occ, free = 0.65, 0.196
    at_occ = int(round(255 - 0.65 * 255))          # p slightly different from occ after rounding
    px = np.array([[at_occ, 255, 0]], dtype=np.uint8)
    grid = pixels_to_occupancy(px, negate=False, occupied_thresh=occ, free_thresh=free)
    p = (255 - at_occ) / 255
    assert grid[0, 0] == (100 if p > occ else -1)
    assert grid[0, 1] == 0 and grid[0, 2] == 100


def test_negate_inverts(tmp_path):
    m = load_map(write_map(tmp_path, [[0, 255]], negate=1))
    assert m.data.tolist() == [[0, 100]]


def test_scale_and_raw_modes():
    px = np.array([[128]], dtype=np.uint8)
    scale = pixels_to_occupancy(px, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode='scale')
    p = (255 - 128) / 255
    assert scale[0, 0] == int(1 + 98 * (p - 0.196) / (0.65 - 0.196))
    raw = pixels_to_occupancy(np.array([[37]], dtype=np.uint8), negate=False, occupied_thresh=0.65,
                              free_thresh=0.196, mode='raw')
    assert raw[0, 0] == 37


def test_scale_alpha_zero_is_unknown():
    px = np.array([[[128, 128, 128, 0], [128, 128, 128, 255]]], dtype=np.uint8)
    grid = pixels_to_occupancy(px, negate=False, occupied_thresh=0.65, free_thresh=0.196, mode='scale')
    assert grid[0, 0] == -1 and grid[0, 1] > 0


@pytest.mark.parametrize('keys, field', [
    (dict(resolution=None), 'resolution'),
    (dict(origin=None), 'origin'),
    (dict(resolution=0), 'resolution'),
    (dict(resolution=-0.05), 'resolution'),
    (dict(mode='fancy'), 'mode'),
    (dict(negate=3), 'negate'),
    (dict(free_thresh=0.9), 'free_thresh'),
    (dict(origin='[1, 2]'), 'origin'),
    (dict(image='missing.pgm'), 'image'),
])
def test_bad_yaml_names_file_and_field(tmp_path, keys, field):
    path = write_map(tmp_path, [[255]], **keys)
    with pytest.raises(ConfigError) as err:
        load_map(path)
    assert field in str(err.value) and 'm.yaml' in str(err.value)
    assert '\n' not in str(err.value)


def test_malformed_yaml(tmp_path):
    path = write_map(tmp_path, [[255]], yaml_text='image: m.pgm\nresolution: [0.05\n')
    with pytest.raises(ConfigError) as err:
        load_map(path)
    assert 'm.yaml' in str(err.value)


def test_truncated_image(tmp_path):
    path = write_map(tmp_path, np.full((50, 50), 255))
    data = (tmp_path / 'm.pgm').read_bytes()
    (tmp_path / 'm.pgm').write_bytes(data[:len(data) // 2])
    with pytest.raises(ConfigError) as err:
        load_map(path)
    assert 'image' in str(err.value)


def test_repository_maps_load(workspace):
    corridor = load_map(f'{workspace}/maps/corridor.yaml')
    assert (corridor.width, corridor.height) == (840, 760) and corridor.resolution == pytest.approx(0.05)
    assert corridor.origin == (-29.8, -34.6, 0.0)
    r, c = corridor.world_to_cell(5.0, 0.0)
    assert corridor.data[r, c] == 0
    r, c = corridor.world_to_cell(5.0, 1.5)
    assert corridor.data[r, c] != 0
    hall = load_map(f'{workspace}/maps/datacenter.yaml')
    r, c = hall.world_to_cell(6.0, 2.5)           # inside a rack row
    assert hall.data[r, c] == 100
    r, c = hall.world_to_cell(10.0, 2.5)          # cross aisle
    assert hall.data[r, c] == 0
