import numpy as np
import pytest

from emulator import CameraResponse, ResponseError
from emulator.io.pcalib import read_pcalib, read_response, write_response

#: Synthetic responses here span the full 12-bit range (the BorealHDR default is 4094).
FULL_12BIT = 4095


def test_pcalib_read_as_given(pcalib_path):
    r = read_response(pcalib_path)
    samples = read_pcalib(pcalib_path)
    assert r.white_level == 4095 and r.g.shape == (4096,)
    # Samples sit at DN 4095*k/255 and are used exactly as given (no renormalisation).
    assert r.g[0] == samples[0] == pytest.approx(0.172934534774103, abs=0)
    assert r.g[4095] == samples[-1] == 255.0
    k = 51  # DN 819 exactly
    assert r.inverse(np.array([819]))[0] == pytest.approx(samples[k], abs=1e-12)
    np.testing.assert_array_equal(r.knots, samples)


@pytest.mark.parametrize(
    "make",
    [
        lambda p: read_response(p),
        lambda p: CameraResponse.linear(FULL_12BIT),
        lambda p: CameraResponse.gamma(2.2, FULL_12BIT),
        lambda p: CameraResponse.gamma(0.45, FULL_12BIT),
        lambda p: CameraResponse.linear(255),
    ],
)
def test_forward_inverse_round_trip_every_integer(make, pcalib_path):
    r = make(pcalib_path)
    d = np.arange(r.white_level + 1)
    np.testing.assert_array_equal(r.forward(r.inverse(d)), d.astype(np.float64))
    assert np.all(np.diff(r.g) > 0)


def test_forward_is_monotone_and_clamped():
    r = CameraResponse.gamma(2.2, FULL_12BIT)
    h = np.linspace(-1, 2, 10001)
    f = r.forward(h)
    assert np.all(np.diff(f) >= 0)
    assert f[0] == 0 and f[-1] == 4095


def test_scalar_and_nd_inputs_agree():
    r = CameraResponse.gamma(2.2, FULL_12BIT)
    d = np.array([[0, 100], [2000, 4095]])
    out = r.inverse(d)
    assert out.shape == (2, 2)
    assert out[1, 0] == r.inverse(np.array(2000))
    assert r.forward(out[1, 0]) == pytest.approx(2000, abs=1e-9)


def _write(tmp_path, text, name="bad.txt"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_bad_tables_name_file_and_defect(tmp_path):
    good = np.linspace(0, 255, 256)
    with pytest.raises(ResponseError, match=r"empty\.txt: empty file"):
        read_response(_write(tmp_path, "   \n", "empty.txt"))
    with pytest.raises(ResponseError, match=r"count\.txt: expected 256 samples .* got 255"):
        read_response(_write(tmp_path, " ".join(map(str, good[:-1])), "count.txt"))
    vals = good.astype(str)
    vals[7] = "nan"
    with pytest.raises(ResponseError, match=r"nan\.txt: 1 non-finite sample\(s\), the first at index 7"):
        read_response(_write(tmp_path, " ".join(vals), "nan.txt"))
    vals = good.copy()
    vals[100] = vals[99]
    with pytest.raises(ResponseError, match=r"flat\.txt: .*not strictly increasing: sample 100"):
        read_response(_write(tmp_path, " ".join(str(float(v)) for v in vals), "flat.txt"))
    vals = good.astype(str)
    vals[3] = "abc"
    with pytest.raises(ResponseError, match=r"word\.txt: sample 3 is 'abc'"):
        read_response(_write(tmp_path, " ".join(vals), "word.txt"))
    with pytest.raises(FileNotFoundError, match="missing.txt"):
        read_response(tmp_path / "missing.txt")


def test_per_dn_table_and_pcalib_round_trip(tmp_path):
    r = CameraResponse.gamma(2.2, FULL_12BIT)
    p = tmp_path / "resp.txt"
    write_response(p, r, n_samples=4096)
    back = read_response(p)
    np.testing.assert_allclose(back.g, r.g, rtol=0, atol=1e-15)


def test_bad_constructor_args():
    with pytest.raises(ResponseError, match="gamma must be finite"):
        CameraResponse.gamma(float("nan"))
    with pytest.raises(ResponseError, match="black_level < white_level"):
        CameraResponse.linear(black_level=5000)
    with pytest.raises(ResponseError, match="strictly increasing"):
        CameraResponse(np.zeros(4096))


def test_with_levels_truncates_table(pcalib_path):
    r = read_response(pcalib_path).with_levels(white_level=4094)
    assert r.white_level == 4094 and r.g.size == 4095
    assert r.g[4094] == read_response(pcalib_path).g[4094]
    with pytest.raises(ResponseError):
        r.with_levels(white_level=4095)
