"""`wideprint submit --cut-out` (docs/cut.md "Through the print server"; issue 35): the job is
print-and-cut on the server, and once it has printed the client writes its cut file, HP-GL/2
or DXF by the name; a job with no cut path is an error, not an empty file."""

import numpy as np
import pikepdf
from support.printcut import make_pdf

from wideprint.app.cli import main
from wideprint.app.client import Client
from wideprint.rip.cutfile import read_dxf, read_hpgl


def test_submit_writes_the_jobs_cut_files(print_server, tmp_path, capsys):
    pdf = make_pdf(tmp_path / "decal.pdf")                  # two CutContour lines
    srv = print_server()
    state = str(srv.state_dir)
    plt, dxf = tmp_path / "out" / "decal.plt", tmp_path / "out" / "decal.dxf"
    plt.parent.mkdir()
    assert main(["submit", "--state-dir", state, "--dpi", "150", "--cut-out", str(plt), str(pdf)]) == 0
    said = capsys.readouterr().out
    assert f"cut file {plt}" in said
    c = Client(srv.state_dir)
    try:
        job = c.jobs()[-1]
        assert job["state"] == "done" and job["settings"]["placement"]["marks"] == "cut"
        assert plt.read_bytes() == c.cut_file(job["id"], "plt")
    finally:
        c.close()
    lines, marks = read_hpgl(str(plt))
    assert len(lines) == 2 and len(marks) == 4                 # a short sheet: the four corners
    assert main(["submit", "--state-dir", state, "--dpi", "150", "--cut-out", str(dxf), str(pdf)]) == 0
    dlines, dmarks = read_dxf(str(dxf))
    assert len(dlines) == 2 and len(dmarks) == 4
    for a, b in zip(sorted(lines, key=lambda p: p[0, 1]), sorted(dlines, key=lambda p: p[0, 1])):
        assert a.shape == b.shape and np.abs(a - b).max() <= 0.025       # HP-GL/2's unit


def test_submit_cut_out_refuses_a_job_without_cut_paths(print_server, tmp_path, capsys):
    pdf = pikepdf.new()
    page = pdf.add_blank_page(page_size=(72, 72))
    page.Contents = pdf.make_stream(b"0 0 0 1 k 10 10 52 52 re f")
    pdf.save(tmp_path / "plain.pdf")
    srv = print_server()
    out = tmp_path / "plain.plt"
    rc = main(["submit", "--state-dir", str(srv.state_dir), "--dpi", "150", "--cut-out", str(out),
               str(tmp_path / "plain.pdf")])
    err = capsys.readouterr().err
    assert rc == 1 and "has no cut paths" in err and "CutContour" in err
    assert not out.exists()
    # another extension: refused before anything is sent
    rc = main(["submit", "--state-dir", str(srv.state_dir), "--cut-out", str(tmp_path / "x.svg"),
               str(tmp_path / "plain.pdf")])
    assert rc == 2 and "must end in .plt, .hpgl or .dxf" in capsys.readouterr().err
    c = Client(srv.state_dir)
    try:
        assert len(c.request("GET", "/v1/jobs?newest=1")["jobs"]) == 1       # only the first job
    finally:
        c.close()
