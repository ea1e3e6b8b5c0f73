"""report.html: self-contained (every image a data URI, nothing fetched), and it opens in a real browser."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from emulator.report.html import (HTML_REPORT_FILE, Thumb, spread_indices, contact_sheet, markdown_to_html, png_data_uri,
                                  thumbnail, write_report)
from emulator.orchestration.runner import run_to_folder

try:
    from tests.emulator.playback.test_playback import write_static_sequence
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

#: Injected first into a copy of the page: records failed resources and script errors, then,
#: once everything has loaded, each image's natural size, into the DOM that --dump-dom prints.
PROBE = """<script>
window.__errors = [];
window.addEventListener("error", function (e) {
  window.__errors.push(e.message || ("resource failed: " + (e.target && (e.target.src || e.target.href))));
}, true);
window.addEventListener("load", function () {
  var imgs = Array.prototype.map.call(document.images, function (i) { return [i.naturalWidth, i.naturalHeight]; });
  var out = document.createElement("pre");
  out.id = "probe";
  out.textContent = JSON.stringify({images: imgs, errors: window.__errors});
  document.body.appendChild(out);
});
</script>"""


def _png(h, w, value):
    from emulator.io.png import encode_png

    return encode_png(np.full((h, w), value, np.uint8))


def test_markdown_tables_lists_code_and_embedded_figures():
    uri = png_data_uri(_png(3, 4, 7))
    got = markdown_to_html("## Results\n\n- a `x<y`\n- b\n\n![fig](f.png)\n\n```\nexposim run\n```\n", {"f.png": uri})
    assert got == ("<h2>Results</h2>\n<ul><li>a <code>x&lt;y</code></li><li>b</li></ul>\n"
                   f'<p><img src="{uri}" alt="fig"></p>\n<pre><code>exposim run</code></pre>')
    assert "not found" in markdown_to_html("![fig](missing.png)")
    with pytest.raises(ValueError, match="PNG bytes"):
        png_data_uri(b"GIF89a")


def test_thumbnail_of_a_bayer_frame_is_grey_8_bit_and_scaled():
    raw = np.full((40, 60), 4094, np.uint16)
    raw[:20] = 0
    th = thumbnail(raw, white_level=4094, width_px=30)
    assert th.dtype == np.uint8 and th.shape == (20, 30)
    assert th[0, 0] == 0 and th[-1, -1] == 255
    half = thumbnail(np.full((4, 4), 1023, np.uint16), white_level=4092, width_px=2)
    assert half[0, 0] == round(255 * 0.25 ** (1 / 2.2))  # gamma-encoded quarter scale


def test_sheet_and_report_files(tmp_path):
    sheet = contact_sheet([("m1", [Thumb(np.zeros((4, 6), np.uint8), "1.00 ms, 0.0 % saturated"),
                                   Thumb(None, "no image")])], title="Sheet")
    assert sheet.count("<img ") == 1 and "no image" in sheet and "grid-template-columns:8em repeat(2,1fr)" in sheet
    (tmp_path / "a.png").write_bytes(_png(5, 5, 200))
    (tmp_path / "b.png").write_bytes(_png(6, 6, 10))
    md, page = write_report(tmp_path, "# T\n\n![shown](a.png)\n\n## Later\n\ntext\n", sheets=[sheet])
    assert md.read_text() == "# T\n\n![shown](a.png)\n\n## Later\n\ntext\n"
    text = page.read_text()
    assert "<title>T</title>" in text
    assert text.index("<h2>Sheet</h2>") < text.index("<h2>Later</h2>") < text.index("<h2>Figures</h2>")
    srcs = re.findall(r'<img src="([^"]+)"', text)
    assert len(srcs) == 3 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert base64.b64decode(srcs[0].split(",", 1)[1]) == (tmp_path / "a.png").read_bytes()
    assert spread_indices(10, 4) == [0, 3, 6, 9]


def test_figures_after_the_text_carry_their_captions_not_their_paths(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "fig.png").write_bytes(_png(5, 5, 200))
    (tmp_path / "other.png").write_bytes(_png(5, 5, 20))
    _, page = write_report(tmp_path, "# T\n\ntext\n", figures={"sub/fig.png": "Matches per method",
                                                               "other.png": "Exposure per cycle"})
    text = page.read_text()
    assert re.findall(r"<figcaption>([^<]*)</figcaption>", text) == ["Matches per method", "Exposure per cycle"]
    assert 'alt="Matches per method"' in text and "sub/fig.png" not in text
    # without a caption the file name is all there is
    _, page = write_report(tmp_path, "# T\n\ntext\n", figures=["other.png"])
    assert re.findall(r"<figcaption>([^<]*)</figcaption>", page.read_text()) == ["other.png"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("html") / "seq"
    write_static_sequence(root, n_cycles=8, shape=(48, 64))
    out = root.parent / "run"
    run_to_folder(root, "classical-30,classical-70", out, save="png16")
    return out


def test_run_report_has_a_contact_sheet_labelled_with_exposure_and_saturation(run_dir):
    text = (run_dir / HTML_REPORT_FILE).read_text()
    assert "What each method saw" in text
    captions = re.findall(r"<figcaption>(cycle \d+: [0-9.]+ ms \(from [0-9.]+ ms\), [0-9.]+ % saturated)</figcaption>",
                          text)
    assert len(captions) == 12  # two methods, six sampled cycles of eight
    assert not re.search(r"<(link|script|iframe)\b", text) and "http://" not in text and "https://" not in text
    srcs = re.findall(r'<img src="([^"]+)"', text)
    assert len(srcs) == 13 and all(s.startswith("data:image/png;base64,") for s in srcs)  # 12 frames + exposure plot


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install -y chromium)")
def test_run_report_opens_in_chromium_with_every_image_decoded_and_no_error(run_dir, tmp_path):
    page = (run_dir / HTML_REPORT_FILE).read_text()
    probe = tmp_path / "probe.html"
    probe.write_text(page.replace("<head>", "<head>" + PROBE, 1))
    got = subprocess.run([CHROMIUM, "--headless", "--disable-gpu", "--no-sandbox", "--enable-logging=stderr", "--v=0",
                          f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000", "--dump-dom",
                          probe.as_uri()], capture_output=True, text=True, timeout=120)
    m = re.search(r'<pre id="probe">(.*?)</pre>', got.stdout, re.DOTALL)
    assert m, got.stderr[-2000:]
    result = json.loads(m.group(1).replace("&quot;", '"'))
    assert result["errors"] == []
    assert len(result["images"]) == 13 and all(w > 0 and h > 0 for w, h in result["images"])
    assert [line for line in got.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line] == []


def test_dataset_report_links_every_unit_page_and_shows_the_first_sheet(tmp_path):
    try:
        from tests.emulator.orchestration.test_datasetrun import make_dataset
    except ImportError:  # tests collected as a package
        from tests.test_datasetrun import make_dataset
    from emulator.orchestration.datasetrun import run_dataset

    root = make_dataset(tmp_path / "root")
    run_dataset(root, tmp_path / "out", methods="classical-50,zhang", group_size=1, scheduler="serial",
                save="png8")
    text = (tmp_path / "out" / HTML_REPORT_FILE).read_text()
    links = re.findall(r'<a href="([^"]+)">', text)
    assert links == [f"{s}/{m}/report.html" for s in ("seqA", "seqB") for m in ("classical-50", "zhang")]
    assert all((tmp_path / "out" / link).is_file() for link in links)
    assert "What each method saw on seqA" in text
    assert len(re.findall(r'<img src="data:image/png;base64,', text)) >= 2


def test_table_cells_with_intervals_stay_numeric():
    got = markdown_to_html("| m | rpe (%) |\n| --- | ---: |\n| a | 1.23 [0.98, 1.51] |\n| b | 0.41 (0.30..0.52) |\n"
                           "| c | n/a |\n")
    assert '<td class="num">1.23 <span class="ci">[0.98, 1.51]</span></td>' in got
    assert '<td class="num">0.41 <span class="ci">(0.30..0.52)</span></td>' in got
    assert "<td>n/a</td>" in got
