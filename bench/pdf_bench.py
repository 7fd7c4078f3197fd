"""A long PDF banner against the same banner as a TIFF: peak memory and time of the RIP
(file -> every stroke's swath words), docs/documents.md.

The banner is vector PostScript (colour bars, a grey ramp, circles, large text every metre)
of --width-m x --length-m; ps2pdf makes the PDF.  Ghostscript also renders it once, before
the clock starts, to an LZW-compressed CMYK TIFF on the device grid (1 px = 1 dot), which is
the "same banner as a TIFF".  Then, each in a fresh process started by rip_bench's small
launcher (so the peak RSS is the job's own):

- wideprint rips the PDF (Ghostscript renders it page-wide, band by band, into the RIP);
- wideprint rips the TIFF with --size pixels.

Both with the same dither and no ink limit (so the CMYK the RIP sees is the same), and the
swath words of both are hashed: they must be identical.  Peak RSS is given for the RIP's
Python process and for the Ghostscript process separately (RUSAGE_SELF / RUSAGE_CHILDREN).

    .venv/bin/python bench/pdf_bench.py                       # 3.2 m x 7 m at 300 dpi, PDF and TIFF
    .venv/bin/python bench/pdf_bench.py --pdf-only            # 3.2 m x 10 m: the PDF alone (the
                                                              # image loader refuses TIFFs over 4 Gpx)
    .venv/bin/python bench/pdf_bench.py --length-m 1 --dpi 150 --keep /tmp/banner
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import zlib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rip_bench import run_measured, rss_floor  # noqa: E402

PT_PER_M = 72 / 0.0254


def banner_ps(path: str, width_m: float, length_m: float) -> None:
    w, h = width_m * PT_PER_M, length_m * PT_PER_M
    with open(path, "w") as f:
        f.write(f"%!PS-Adobe-3.0\n<< /PageSize [{w:.2f} {h:.2f}] >> setpagedevice\n")
        f.write("/Helvetica-Bold findfont 300 scalefont setfont\n")
        metres = int(length_m) + 1
        f.write(f"0 1 {metres - 1} {{ /m exch def /y m {PT_PER_M:.4f} mul def\n")
        # colour bars across, a grey ramp, circles, the metre number in large text
        f.write(f"  0 1 23 {{ /i exch def i 24 div 1 i 24 div sub 0.5 0 setcmykcolor\n"
                f"    i {w / 24:.3f} mul y {w / 24:.3f} 600 rectfill }} for\n")
        f.write(f"  0 1 99 {{ /i exch def i 100 div setgray i {w / 100:.3f} mul y 700 add {w / 100:.3f} 300 "
                f"rectfill }} for\n")
        f.write(f"  0 1 9 {{ /i exch def 0.1 i mul 0.9 0.2 setrgbcolor newpath i {w / 10:.3f} mul 250 add "
                f"y 1400 add 200 0 360 arc fill }} for\n")
        f.write("  0 0 0 1 setcmykcolor 200 y 1800 add moveto (WIDEPRINT  metre ) show m 3 string cvs show\n")
        f.write("} for\nshowpage\n")


def child(path: str, dither: str, dpi: int, pixels: bool) -> None:
    import resource
    t0 = time.perf_counter()
    from wideprint.rip.pipeline import RipJob, RipSettings
    from wideprint.rip.profile import load_profile
    from wideprint.rip.settings import Placement
    settings = RipSettings(dpi=dpi, dither=dither, ink_limit=400,
                           placement=Placement(size="pixels" if pixels else "physical"))
    job = RipJob(path, settings, load_profile())
    t_open = time.perf_counter() - t0
    crc, passes, dots = 0, 0, 0
    t1 = time.perf_counter()
    for p in job.strokes():
        crc = zlib.crc32(p.words.tobytes(), crc)
        crc = zlib.crc32(bytes(f"{p.index}:{p.direction}:{p.top_row}:{p.first_column}", "ascii"), crc)
        passes += 1
        dots += int(p.dots.sum())
    t_rip = time.perf_counter() - t1
    job.close()
    print(json.dumps(dict(width=job.width, height=job.height, crc=crc, passes=passes, dots=dots, t_open=t_open,
                          t_rip=t_rip, rss_self=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                          rss_gs=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width-m", type=float, default=3.2)
    ap.add_argument("--length-m", type=float, default=None,
                    help="banner length (default 7 m with the TIFF, 10 m with --pdf-only)")
    ap.add_argument("--dpi", type=int, default=300)
    ap.add_argument("--dither", default="bayer")
    ap.add_argument("--keep", metavar="DIR", help="make the files there and keep them")
    ap.add_argument("--pdf-only", action="store_true", help="no TIFF (the image loader refuses TIFFs over "
                    "4 Gpx: 3.2 m x 10 m at 300 x 370.53 dpi is 5.5 Gpx)")
    ap.add_argument("--child", nargs=2, metavar=("FILE", "KIND"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child[0], args.dither, args.dpi, args.child[1] == "pixels")
        return 0
    if args.length_m is None:
        args.length_m = 10.0 if args.pdf_only else 7.0
    d = args.keep or tempfile.mkdtemp(prefix="wideprint-pdfbench-")
    os.makedirs(d, exist_ok=True)
    ps, pdf, tif = (os.path.join(d, f"banner.{x}") for x in ("ps", "pdf", "tif"))
    ypi = 25400 / 68.55
    banner_ps(ps, args.width_m, args.length_m)
    t = time.perf_counter()
    subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite", f"-sOutputFile={pdf}", ps],
                   check=True)
    t_pdf = time.perf_counter() - t
    from wideprint.rip.ghostscript import colour_args
    t_tif = 0.0
    if not args.pdf_only:
        t = time.perf_counter()
        subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=tiff32nc", "-sCompression=lzw",
                        f"-r{args.dpi}x{ypi:.6f}", *colour_args(None, None, "relative"), f"-sOutputFile={tif}",
                        pdf], check=True)
        t_tif = time.perf_counter() - t
    print(f"banner {args.width_m} x {args.length_m} m at {args.dpi} x {ypi:.2f} dpi, dither {args.dither}; "
          f"PDF {os.path.getsize(pdf) / 1e3:.0f} kB ({t_pdf:.1f} s)"
          + ("" if args.pdf_only else f", TIFF {os.path.getsize(tif) / 1e6:.0f} MB LZW ({t_tif:.1f} s to render "
                                      f"with gs)") + f"; launcher floor {rss_floor():.0f} MB")
    print(f"\n{'input':26s} {'dots':>19s} {'Mpx':>7s} {'wall s':>7s} {'cpu s':>7s} {'Mpx/s':>6s} "
          f"{'RIP RSS MB':>10s} {'gs RSS MB':>9s}  swath words", flush=True)
    rows = []
    runs = [("PDF (Ghostscript -> RIP)", pdf, "physical")]
    if not args.pdf_only:
        runs.append(("TIFF, --size pixels", tif, "pixels"))
    for name, path, kind in runs:
        r = run_measured([sys.executable, os.path.abspath(__file__), "--child", path, kind, "--dither", args.dither,
                          "--dpi", str(args.dpi)])
        if not r.ok:
            print(f"{name}: FAILED: {r.err.strip().splitlines()[-1] if r.err.strip() else r.out[-500:]}")
            continue
        i = json.loads(r.out.strip().splitlines()[-1])
        rows.append(i)
        mpx = i["width"] * i["height"] / 1e6
        print(f"{name:26s} {i['width']:>9,} x {i['height']:<8,} {mpx:7.0f} {r.wall:7.1f} {r.cpu:7.1f} "
              f"{mpx / i['t_rip']:6.1f} {i['rss_self']:10.0f} {i['rss_gs'] or 0:9.0f}  crc {i['crc']:08x}", flush=True)
    same = len(rows) == 2 and rows[0]["crc"] == rows[1]["crc"] and rows[0]["passes"] == rows[1]["passes"]
    if len(rows) == 2:
        print(f"\nswath words identical: {'yes' if same else 'NO'}; peak RSS of the RIP process "
              f"{rows[0]['rss_self']:.0f} MB (PDF) vs {rows[1]['rss_self']:.0f} MB (TIFF)")
    if not args.keep:
        for p in (ps, pdf, tif):
            if os.path.exists(p):
                os.unlink(p)
        os.rmdir(d)
    ok = len(rows) == len(runs) and (args.pdf_only or same)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
