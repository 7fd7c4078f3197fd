"""`wideprint spot list|show|import|export|remove|swatch|pick|forget`: named colour
libraries, their recipes per media, and the swatch book (docs/spot.md)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, _say, _where, family, measure_options

#: the swatch book's grid, in --step units (docs/spot.md "The swatch book")
L_STEPS = (-2, -1, 0, 1, 2)
C_STEPS = (-1, 0, 1)
H_STEPS = (-1, 0, 1)


def _book():
    from ...rip.spot import SpotBook
    return SpotBook()


def _media(args):
    from ..medialib import DEFAULT_MEDIA, find
    m = find(getattr(args, "media", None) or DEFAULT_MEDIA)
    if not m.icc_path.is_file():
        raise ValueError(f"media {m.name!r}: its profile {m.icc_path} is missing")
    return m


def _spot(book, name: str):
    s = book.find(name)
    if s is None:
        raise ValueError(f"no spot colour {name!r} in the libraries (wideprint spot list)")
    return s


def cmd_list(args) -> int:
    libs = _book().libraries()
    if args.json:
        print(json.dumps([{"library": lib.name, "colours": [{"name": s.name, "lab": list(s.lab)}
                                                            for s in lib.colours]} for lib in libs], indent=1))
        return EXIT_OK
    if not libs:
        print(f"no spot libraries in {_book().folder} (wideprint spot import FILE)")
    for lib in libs:
        print(f"{lib.name} ({len(lib.colours)} colours)")
        for s in lib.colours:
            print(f"  {s.name:32s} L {s.lab[0]:6.2f}  a {s.lab[1]:7.2f}  b {s.lab[2]:7.2f}")
    return EXIT_OK


def cmd_show(args) -> int:
    book = _book()
    spot = _spot(book, args.name)
    media = _media(args)
    dpi = int(media.values["dpi"])
    res = book.resolve(spot.name, media.name, str(media.icc_for(dpi)))
    out = dict(res.as_dict(), library=spot.library)
    if args.json:
        print(json.dumps(out, indent=1))
        return EXIT_OK
    print(f"{spot.name} (library {spot.library}): L {spot.lab[0]:.2f} a {spot.lab[1]:.2f} b {spot.lab[2]:.2f}")
    how = {"recipe": "the recipe saved for it (spot pick)", "library": "its Lab through the media's profile"}
    print(f"  on {media.name}: {how.get(res.resolved, res.resolved)}")
    if res.cmyk is not None:
        print("  recipe C {:.1f} %  M {:.1f} %  Y {:.1f} %  K {:.1f} %".format(*[v * 100 for v in res.cmyk]))
    if res.de2000 is not None:
        print(f"  ΔE2000 to target {res.de2000:.2f}" + ("" if res.in_gamut else "  (out of gamut)"))
    return EXIT_OK


def cmd_import(args) -> int:
    from ...rip.spot import read_file
    warnings: list[str] = []
    spots = read_file(args.file, warnings)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    library = args.library or Path(args.file).stem
    lib = _book().add(spots, library, args.replace)
    print(f"{len(spots)} colours imported into library {lib.name} ({len(lib.colours)} colours)")
    return EXIT_OK


def cmd_export(args) -> int:
    from ...rip.spot import write_cxf3, write_text
    lib = _book().library(args.library)
    out = Path(args.output)
    if out.suffix.lower() in (".cxf", ".xml"):
        out.write_bytes(write_cxf3(lib.colours, lib.name))
    else:
        out.write_text(write_text(lib.colours))
    print(f"{len(lib.colours)} colours of {lib.name} -> {out}")
    return EXIT_OK


def cmd_remove(args) -> int:
    book = _book()
    if args.library:
        book.remove_library(args.library)
        print(f"removed library {args.library}")
    elif args.name:
        s = book.remove(args.name)
        print(f"removed {s.name} from {s.library or 'its library'}")
    else:
        raise ValueError("give a colour NAME or --library LIB")
    return EXIT_OK


def cmd_forget(args) -> int:
    media = _media(args)
    done = _book().forget_recipe(media.name, args.name)
    print(f"{args.name} on {media.name}: " + ("recipe removed (the profile's from now on)" if done
                                              else "had no saved recipe"))
    return EXIT_OK


# -- the swatch book -----------------------------------------------------------------------
def variations(lab, step: float) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """The book's Lab aims: the centre first, then L x C x h steps (hue as a distance
    along the hue circle at the colour's chroma)."""
    L, a, b = (float(v) for v in lab)
    C = math.hypot(a, b)
    h = math.atan2(b, a)
    grid = [(0, 0, 0)] + [(i, j, k) for i in L_STEPS for j in C_STEPS for k in H_STEPS
                          if (i, j, k) != (0, 0, 0)]
    out = []
    for i, j, k in grid:
        c2 = max(0.0, C + j * step)
        h2 = h + (k * step) / max(C, 1.0)
        out.append((min(100.0, max(0.0, L + i * step)), c2 * math.cos(h2), c2 * math.sin(h2)))
    return np.array(out), grid


def swatch_recipes(lab, icc: str, step: float, recipe=None) -> tuple[np.ndarray, list]:
    """Ink fractions (n, 4) of the book: through the profile around the Lab, or around a
    saved recipe (the recipe plus the profile's change for the same move in Lab)."""
    from ...rip.spot import cmyk_to_lab, lab_to_cmyk
    if recipe is None:
        aims, grid = variations(lab, step)
        return np.clip(lab_to_cmyk(aims, icc), 0, 1), grid
    centre = cmyk_to_lab(np.array([recipe]), icc)[0]
    aims, grid = variations(centre, step)
    moved = lab_to_cmyk(aims, icc)
    return np.clip(np.asarray(recipe)[None] + moved - moved[0:1], 0, 1), grid


def cmd_swatch(args) -> int:
    from ...rip.profile import load_profile
    from ...rip.spot import delta_e2000, now
    from .. import mediacal
    from ..medialib import apply_to_profile
    book = _book()
    spot = _spot(book, args.name)
    media = _media(args)
    dpi = int(media.values["dpi"])
    icc = str(media.icc_for(dpi))
    saved = book.recipe(media.name, spot.name)
    cmyk, grid = swatch_recipes(spot.lab, icc, args.step, saved["cmyk"] if saved else None)
    levels = np.clip(np.round(cmyk * 255), 0, 255).astype(np.uint8)
    values = np.concatenate([levels, np.zeros((1, 4), np.uint8)])        # the last: paper
    profile = load_profile(args.profile)
    pr = mediacal.printer_for(media.values, profile, tuple(args.inject or ()), _where(args))
    _say(args)(f"swatch book of {spot.name} on {media.name}: {len(levels)} patches "
               f"(step {args.step:g} ΔE), printing and measuring")
    lab = pr.measure(values, apply_to_profile(media, profile, dpi), name="swatch")
    paper = lab[-1]
    absolute = lab[:-1]
    relative = mediacal.bradford_relative(absolute, paper)
    target = np.array([spot.lab])
    de_rel = delta_e2000(target.repeat(len(levels), 0), relative)
    de_abs = delta_e2000(target.repeat(len(levels), 0), absolute)
    patches: list[dict] = [{"patch": i, "steps": list(grid[i]), "cmyk": [round(float(v) / 255, 5) for v in levels[i]],
                "lab": [round(float(v), 3) for v in absolute[i]],
                "lab_relative": [round(float(v), 3) for v in relative[i]],
                "de2000": round(float(de_abs[i]), 3), "de2000_relative": round(float(de_rel[i]), 3)}
               for i in range(len(levels))]
    data = {"name": spot.name, "media": media.name, "target": list(spot.lab), "step": args.step,
            "around": "recipe" if saved else "library", "printed": now(),
            "paper_lab": [round(float(v), 3) for v in paper], "patches": patches}
    path = book.save_swatch(media.name, spot.name, data)
    best = min(patches, key=lambda p: p["de2000"])
    out = {"name": spot.name, "media": media.name, "swatch": str(path), "patches": len(patches),
           "centre_de2000": patches[0]["de2000"], "best_patch": best["patch"],
           "best_de2000": best["de2000"], "best_cmyk": best["cmyk"]}
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"{spot.name} on {media.name}: centre ΔE2000 {patches[0]['de2000']:.2f}, best patch "
              f"{best['patch']} ΔE2000 {best['de2000']:.2f} (C/M/Y/K "
              + "/".join(f"{v * 100:.1f}" for v in best["cmyk"]) + f" %); measured: {path}")
        print(f"  `wideprint spot pick {json.dumps(spot.name)} --media {media.name}` stores it")
    return EXIT_OK


def cmd_pick(args) -> int:
    book = _book()
    spot = _spot(book, args.name)
    media = _media(args)
    sw = book.swatch(media.name, spot.name)
    if not sw:
        raise ValueError(f"no swatch book of {spot.name!r} on {media.name} measured yet "
                         f"(wideprint spot swatch {json.dumps(spot.name)} --media {media.name})")
    patches = sw["patches"]
    if args.patch is not None:
        if not 0 <= args.patch < len(patches):
            raise ValueError(f"--patch {args.patch}: the book has patches 0..{len(patches) - 1}")
        p = patches[args.patch]
    else:
        p = min(patches, key=lambda q: q["de2000"])
    entry = book.save_recipe(media.name, spot.name, p["cmyk"], lab=p["lab"], de2000=p["de2000"],
                             de2000_relative=p["de2000_relative"], source="swatch", swatch=sw["printed"],
                             patch=p["patch"])
    out = {"name": spot.name, "media": media.name, "patch": p["patch"], **entry}
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"{spot.name} on {media.name}: patch {p['patch']} stored as the recipe (C/M/Y/K "
              + "/".join(f"{v * 100:.1f}" for v in p["cmyk"]) + f" %), ΔE2000 {p['de2000']:.2f} to target "
              f"(relative to the paper {p['de2000_relative']:.2f})")
    return EXIT_OK


def summary(spots: list[dict]) -> str:
    """A job's spots in one line: `Brand Red (library, ΔE 0.4), CutContour (cut: not printed)`."""
    parts = []
    for sp in spots:
        how = sp.get("resolved", "?")
        if how == "cut":
            parts.append(f"{sp['name']} (cut: not printed)")
        elif sp.get("de2000") is not None:
            parts.append(f"{sp['name']} ({how}, ΔE {sp['de2000']:.1f}"
                         + ("" if sp.get("in_gamut", True) else ", out of gamut") + ")")
        else:
            parts.append(f"{sp['name']} ({how})")
    return ", ".join(parts)


def cmd_spot(args) -> int:
    from ..argyll import ArgyllError
    try:
        return args.spot_func(args)
    except (ValueError, KeyError, OSError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"wideprint spot {args.spot_command}: {msg}", file=sys.stderr)
        return EXIT_USAGE
    except ArgyllError as exc:
        print(f"wideprint spot {args.spot_command}: {exc}", file=sys.stderr)
        return EXIT_FAILED


def add_parser(sub) -> None:
    _, cmd = family(sub, "spot", "spot colours: named colour libraries, recipes per media, "
                    "the swatch book (docs/spot.md)", "spot_command", cmd_spot, "spot_func")

    q = cmd("list", cmd_list, "the libraries and their colours")
    q.add_argument("--json", action="store_true")
    q = cmd("show", cmd_show, "a colour: its Lab and how it resolves on a media")
    q.add_argument("name")
    q.add_argument("--media", metavar="M", help="default: the shipped default media")
    q.add_argument("--json", action="store_true")
    q = cmd("import", cmd_import, "a CxF3 file or a 'NAME: L a b' text list into a library")
    q.add_argument("file")
    q.add_argument("--library", metavar="LIB", help="default: the file's name")
    q.add_argument("--replace", action="store_true", help="overwrite colours of the same name")
    q = cmd("export", cmd_export, "a library as CxF3 (.cxf) or a text list (any other name)")
    q.add_argument("library")
    q.add_argument("-o", "--output", required=True, metavar="FILE")
    q = cmd("remove", cmd_remove, "a colour, or a whole library")
    q.add_argument("name", nargs="?")
    q.add_argument("--library", metavar="LIB")
    q = cmd("forget", cmd_forget, "drop the recipe saved for a colour on a media")
    q.add_argument("name")
    q.add_argument("--media", metavar="M")
    q = cmd("swatch", cmd_swatch, "print and measure the swatch book: the colour and L, C, h "
            "steps around it")
    q.add_argument("name")
    q.add_argument("--media", metavar="M")
    q.add_argument("--step", type=float, default=2.0, metavar="DE", help="step in ΔE units (default 2)")
    measure_options(q)
    q = cmd("pick", cmd_pick, "store the swatch book's best patch (or --patch N) as the recipe")
    q.add_argument("name")
    q.add_argument("--media", metavar="M")
    q.add_argument("--patch", type=int, metavar="N")
    q.add_argument("--json", action="store_true")
