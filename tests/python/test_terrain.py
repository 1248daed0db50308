"""Tests of the Python module `terrain` (python/terrain_module.cpp), run by ctest through pytest."""
import os

import numpy as np
import pytest

import terrain

DATA = os.environ.get("TERRAIN_SHARED_DATA", "")
RAINIER = os.path.join(DATA, "srtm3_N46W122_rainier_adams_cascades.hgt")


def shared(path):
    """A shared DEM; missing data fails in CI and skips elsewhere."""
    if not os.path.exists(path):
        if os.environ.get("CI") == "true":
            pytest.fail(f"shared data missing in CI: {path}")
        pytest.skip(f"shared data missing: {path}")
    return path


def synthetic(h, w, seed=1):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    return (1000 + 300 * np.sin(x / 17.0) * np.cos(y / 23.0) + rng.normal(0, 3, (h, w))).astype(np.float64)


def test_lossless_int16_array_round_trips_exactly(tmp_path):
    grid = np.round(synthetic(203, 301)).astype(np.int16)
    report = terrain.build(grid, str(tmp_path / "a.pyr"), lossless=True)
    assert report["finest_max_m"] == 0
    p = terrain.open(str(tmp_path / "a.pyr"))
    assert p.levels[-1] == (301, 203)
    for (cw, ch), (fw, fh) in zip(p.levels, p.levels[1:]):  # ceil-half extent rule
        assert (cw, ch) == ((fw + 1) // 2, (fh + 1) // 2)
    a = p.read(p.level_count - 1, 0, 0, 301, 203)
    assert a.dtype == np.float32 and a.shape == (203, 301)
    np.testing.assert_array_equal(a, grid.astype(np.float32))
    assert p.info["error_mode"] == "lossless"


def test_window_equals_the_same_part_of_the_whole_level(tmp_path):
    report = terrain.build(synthetic(260, 190, 2), str(tmp_path / "w.pyr"), step=2.0)
    assert 0 < report["finest_rms_m"] < 2.0  # a transform step: the error is below the step in rms
    p = terrain.open(str(tmp_path / "w.pyr"))
    for level in range(p.level_count):
        w, h = p.levels[level]
        whole = p.read(level, 0, 0, w, h)
        x, y, ww, hh = w // 5, h // 3, max(1, w // 2), max(1, h // 2)
        np.testing.assert_array_equal(p.read(level, x, y, ww, hh), whole[y:y + hh, x:x + ww])


def test_nan_marks_voids_and_rms_target_holds(tmp_path):
    grid = synthetic(300, 280, 3)
    grid[40:60, 100:130] = np.nan
    report = terrain.build(grid, str(tmp_path / "v.pyr"), rms=1.0)
    assert 0.9 <= report["finest_rms_m"] <= 1.1
    p = terrain.open(str(tmp_path / "v.pyr"))
    a = p.read(p.level_count - 1, 0, 0, 280, 300)
    assert np.isnan(a[40:60, 100:130]).all()
    valid = ~np.isnan(grid)
    assert not np.isnan(a[valid]).any()
    assert p.info["void_count"] == 20 * 30
    rms = float(np.sqrt(np.mean((a[valid] - grid[valid]) ** 2)))
    assert rms <= 1.1


def test_srtm_tile_geotransform_and_exact_lossless_values(tmp_path):
    path = shared(RAINIER)
    terrain.build(path, str(tmp_path / "r.pyr"), lossless=True)
    p = terrain.open(str(tmp_path / "r.pyr"))
    # N46W122: the north-west sample centre is at 47N 122W, samples 3 arc-seconds apart.
    x0, dx, rx, y0, ry, dy = p.geotransform
    assert (rx, ry) == (0.0, 0.0)
    assert dx == pytest.approx(3 / 3600) and dy == pytest.approx(-3 / 3600)
    assert x0 == pytest.approx(-122 - 1.5 / 3600) and y0 == pytest.approx(47 + 1.5 / 3600)
    raw = np.fromfile(path, dtype=">i2").reshape(1201, 1201).astype(np.float32)
    np.testing.assert_array_equal(p.read(p.level_count - 1, 100, 250, 300, 200), raw[250:450, 100:400])


def test_projected_ascii_grid_keeps_its_geotransform_and_crs(tmp_path):
    """A UTM ASCII grid (+ .prj): the geotransform is the stored one, the CRS its EPSG code and WKT."""
    grid = np.round(synthetic(30, 40)).astype(np.int32)
    asc = tmp_path / "utm.asc"
    header = "ncols 40\nnrows 30\nxllcorner 500000\nyllcorner 5199100\ncellsize 30\n"
    asc.write_text(header + "\n".join(" ".join(str(v) for v in row) for row in grid) + "\n")
    wkt = 'PROJCS["WGS_1984_UTM_Zone_10N",GEOGCS["GCS_WGS_1984"],UNIT["Meter",1.0]]'
    (tmp_path / "utm.prj").write_text(wkt)
    terrain.build(str(asc), str(tmp_path / "u.pyr"), lossless=True)
    p = terrain.open(str(tmp_path / "u.pyr"))
    assert p.geotransform == (500000.0, 30.0, 0.0, 5200000.0, 0.0, -30.0)
    assert p.info["crs_epsg"] == 32610
    assert p.info["crs_text"] == wkt
    np.testing.assert_array_equal(p.read(p.level_count - 1, 0, 0, 40, 30), grid.astype(np.float32))


def test_errors_carry_the_library_code(tmp_path):
    with pytest.raises(terrain.Error) as missing:
        terrain.open(str(tmp_path / "missing.pyr"))
    assert missing.value.code == "not found" and "missing.pyr" in str(missing.value)
    junk = tmp_path / "junk.pyr"
    junk.write_bytes(b"not a pyramid at all, just text" * 4)
    with pytest.raises(terrain.Error) as bad:
        terrain.open(str(junk))
    assert bad.value.code == "unknown type or format"
    terrain.build(np.zeros((40, 40), np.int16), str(tmp_path / "z.pyr"))
    p = terrain.open(str(tmp_path / "z.pyr"))
    with pytest.raises(terrain.Error) as outside:
        p.read(p.level_count - 1, 30, 30, 20, 20)
    assert outside.value.code == "invalid option"
    with pytest.raises(terrain.Error):
        terrain.build(np.zeros((4, 4, 4)), str(tmp_path / "cube.pyr"))
    with pytest.raises(terrain.Error):
        terrain.build(np.zeros((8, 8)), str(tmp_path / "two.pyr"), rms=1.0, step=2.0)


def test_read_equals_the_pyramid_extract_window(tmp_path):
    import json
    import subprocess

    grid = synthetic(301, 257, 4)
    terrain.build(grid, str(tmp_path / "e.pyr"), rms=0.5)
    p = terrain.open(str(tmp_path / "e.pyr"))
    level = p.level_count - 2
    x, y, w, h = 11, 7, 90, 61
    out = tmp_path / "e.raw"
    tool = os.path.join(os.environ["TERRAIN_BIN"], "pyramid-extract")
    subprocess.run([tool, str(tmp_path / "e.pyr"), "-o", str(out), "--level", str(level), "--window",
                    f"{x},{y},{w},{h}", "-q"], check=True)
    side = json.load(open(str(out) + ".json"))
    assert (side["width"], side["height"], side["type"]) == (w, h, "float32")
    extracted = np.fromfile(out, dtype="<f4").reshape(h, w)
    np.testing.assert_array_equal(p.read(level, x, y, w, h), extracted)


def test_downsample_choice_both_lossless_and_bad_value_rejected(tmp_path):
    grid = np.round(synthetic(520, 600, 3)).astype(np.int16)
    for choice in ("wavelet", "optimal", "point", "auto"):
        path = str(tmp_path / f"{choice}.pyr")
        assert terrain.build(grid, path, lossless=True, downsample=choice)["finest_max_m"] == 0
        p = terrain.open(path)
        assert p.level_count >= 3
        np.testing.assert_array_equal(p.read(p.level_count - 1, 0, 0, 600, 520), grid.astype(np.float32))
    # The two D give different coarse levels (the same finest one).
    a, b = terrain.open(str(tmp_path / "wavelet.pyr")), terrain.open(str(tmp_path / "optimal.pyr"))
    w, h = a.levels[0]
    assert not np.array_equal(a.read(0, 0, 0, w, h), b.read(0, 0, 0, w, h))
    # Point sampling (auto's choice for lossless): every coarse sample is an input sample.
    for name in ("point", "auto"):
        c = terrain.open(str(tmp_path / f"{name}.pyr"))
        k = c.level_count - 1
        cw, ch = c.levels[0]
        np.testing.assert_array_equal(c.read(0, 0, 0, cw, ch), grid[:: 2**k, :: 2**k][:ch, :cw].astype(np.float32))
    with pytest.raises(ValueError):
        terrain.build(grid, str(tmp_path / "bad.pyr"), lossless=True, downsample="box")


def test_level_schedule_options(tmp_path):
    grid = np.round(synthetic(600, 560, 5)).astype(np.int16)  # 3 levels
    given = terrain.build(grid, str(tmp_path / "r.pyr"), step=8.0, coarse_step_ratio=0.5)
    steps = given["level_step_metres"]
    assert given["coarse_step_ratio"] == 0.5
    assert steps[-1] == pytest.approx(8.0)
    assert steps[-2] == pytest.approx(4.0)
    assert steps[-3] == pytest.approx(2.0)
    screen = terrain.build(grid, str(tmp_path / "s.pyr"), step=2.0, level_error="screen")
    assert screen["level_step_metres"][-2] == pytest.approx(4.0)
    assert screen["coarse_step_ratio"] == 1
    calibrated = terrain.build(grid, str(tmp_path / "a.pyr"), rms=1.0)
    assert 0 < calibrated["coarse_step_ratio"] <= 1
    assert calibrated["finest_rms_m"] <= 1.0
    with pytest.raises(terrain.Error) as bad:
        terrain.build(grid, str(tmp_path / "bad.pyr"), step=8.0, coarse_step_ratio=1.5)
    assert bad.value.code == "invalid option"
    with pytest.raises(terrain.Error):
        terrain.build(grid, str(tmp_path / "bad.pyr"), lossless=True, coarse_step_ratio=0.5)
    with pytest.raises(ValueError):
        terrain.build(grid, str(tmp_path / "bad.pyr"), step=8.0, level_error="relative")
