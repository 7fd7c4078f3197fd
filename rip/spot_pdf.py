"""A PDF's spot colours: which it uses, and the copy Ghostscript renders with every library
colour printing its recipe and every cut colour removed from the print (docs/spot.md
"Rendering").

pikepdf (QPDF) reads and writes the file; Ghostscript still renders it (rip/ghostscript.py).
By hand here only what no library does: walking the colour spaces of a page's resources
and the small graphics-state machine that ends a path painted in a cut colour without
painting it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Iterator

from .cutnames import is_cut_name

__all__ = ["SpotUse", "spot_names", "rewrite"]

PROCESS = {"cyan": (1.0, 0.0, 0.0, 0.0), "magenta": (0.0, 1.0, 0.0, 0.0),
           "yellow": (0.0, 0.0, 1.0, 0.0), "black": (0.0, 0.0, 0.0, 1.0)}
NONE_NAMES = ("None", "All")          # the PDF's reserved Separation names


@dataclass
class SpotUse:
    """The spot colour names a document uses, and how they appear."""
    names: dict[str, str] = field(default_factory=dict)     # name -> separation | devicen | cut

    def add(self, name: str, kind: str) -> None:
        if name in NONE_NAMES or (kind == "devicen" and name.casefold() in PROCESS):
            return
        if is_cut_name(name):
            kind = "cut"
        self.names.setdefault(name, kind)


def _pikepdf():
    try:
        import pikepdf
    except ImportError:           # a dependency of setup.cfg: fail loudly, never print wrong
        raise RuntimeError("spot colours need pikepdf (pip install pikepdf)") from None
    return pikepdf


def _name(obj) -> str:
    s = str(obj)
    return s[1:] if s.startswith("/") else s


def _cs_kind(cs):
    """('separation', [name]) | ('devicen', [names]) | (None, []) of a colour space object;
    Indexed and Pattern spaces give their base's."""
    pikepdf = _pikepdf()
    if isinstance(cs, pikepdf.Array) and len(cs):
        head = _name(cs[0])
        if head == "Separation" and len(cs) >= 4:
            return "separation", [_name(cs[1])]
        if head == "DeviceN" and len(cs) >= 4:
            return "devicen", [_name(n) for n in cs[1]]
        if head in ("Indexed", "I") and len(cs) >= 2:
            return _cs_kind(cs[1])
        if head == "Pattern" and len(cs) >= 2:
            return _cs_kind(cs[1])
    return None, []


def _spaces(resources, seen: set) -> Iterator:
    """Every colour space object reachable from a resource dictionary (colour spaces,
    images, shadings, forms and patterns with their own resources)."""
    pikepdf = _pikepdf()
    if not isinstance(resources, pikepdf.Dictionary):
        return
    key = resources.objgen if resources.is_indirect else None
    if key is not None:
        if key in seen:
            return
        seen.add(key)
    for cs in (resources.get("/ColorSpace") or {}).values() if isinstance(
            resources.get("/ColorSpace"), pikepdf.Dictionary) else ():
        yield cs
    for sub in ("/XObject", "/Pattern", "/Shading"):
        d = resources.get(sub)
        if not isinstance(d, pikepdf.Dictionary):
            continue
        for obj in d.values():
            if not isinstance(obj, (pikepdf.Dictionary, pikepdf.Stream)):
                continue
            if obj.is_indirect:
                if ("obj",) + tuple(obj.objgen) in seen:
                    continue
                seen.add(("obj",) + tuple(obj.objgen))
            if "/ColorSpace" in obj:
                yield obj.ColorSpace
            if "/Shading" in obj and isinstance(obj.Shading, pikepdf.Dictionary) and "/ColorSpace" in obj.Shading:
                yield obj.Shading.ColorSpace
            if "/Resources" in obj:
                yield from _spaces(obj.Resources, seen)


def _appearances(page) -> Iterator:
    """The appearance streams (with resources) of a page's annotations."""
    pikepdf = _pikepdf()
    for annot in page.obj.get("/Annots") or []:
        ap = annot.get("/AP") if isinstance(annot, pikepdf.Dictionary) else None
        if not isinstance(ap, pikepdf.Dictionary):
            continue
        for v in ap.values():
            streams = [v] if isinstance(v, pikepdf.Stream) else \
                list(v.values()) if isinstance(v, pikepdf.Dictionary) else []
            yield from (s for s in streams if isinstance(s, pikepdf.Stream) and "/Resources" in s)


def _page_resources(pdf) -> Iterator:
    for page in pdf.pages:
        yield page.obj.get("/Resources")
        for s in _appearances(page):
            yield s.Resources


def spot_names(path: str) -> SpotUse:
    """The Separation and DeviceN names of every page (its resources, forms, patterns,
    images, shadings, annotation appearances)."""
    pikepdf = _pikepdf()
    use = SpotUse()
    with pikepdf.open(path) as pdf:
        seen: set = set()
        for res in _page_resources(pdf):
            for cs in _spaces(res, seen):
                kind, names = _cs_kind(cs)
                for n in names:
                    use.add(n, kind or "separation")
    return use


# -- the rewrite ---------------------------------------------------------------------------
def _pwl(samples) -> str:
    """PostScript calculator code taking the tint t on the stack to the piecewise-linear
    curve through `samples` (at tints 0, 1/(S-1), ..., 1): a binary tree of `ifelse`."""
    last = len(samples) - 1

    def seg(lo: int, hi: int) -> str:
        if hi - lo == 1:
            slope = (samples[hi] - samples[lo]) * last
            return f"{lo / last:.5f} sub {slope:.5f} mul {samples[lo]:.5f} add"
        mid = (lo + hi) // 2
        return f"dup {mid / last:.5f} lt {{ {seg(lo, mid)} }} {{ {seg(mid, hi)} }} ifelse"
    return seg(0, last)


def _type4(recipes: list) -> bytes:
    """A PostScript calculator function: n tints -> 4 inks, each ink the sum over the
    colorants of tint x recipe (a colorant with a recipe: 4 ink fractions) or of the
    colorant's own curve (one with samples: an (S, 4) array of inks at S even tints, the
    alternate evaluated for it alone), at most 1."""
    if all(len(r) == 4 and not hasattr(r[0], "__len__") for r in recipes):
        return _type4_linear(recipes)
    n = len(recipes)
    ops: list[str] = []
    for j in range(4):
        ops.append("0")                                   # the ink's sum, above j inks
        for i, r in enumerate(recipes):
            curve = [float(v[j]) for v in r] if hasattr(r[0], "__len__") else None
            if (curve is None and r[j] == 0) or (curve is not None and max(curve) == 0):
                continue
            ops.append(f"{(n - 1 - i) + j + 1} index")
            ops.append(f"{r[j]:.5f} mul add" if curve is None else f"{_pwl(curve)} add")
        ops.append("dup 1 gt { pop 1 } if dup 0 lt { pop 0 } if")
    ops.append(f"{n + 4} 4 roll" if n else "")
    ops += ["pop"] * n
    return ("{ " + " ".join(o for o in ops if o) + " }").encode()


def _type4_linear(recipes: list[tuple[float, ...]]) -> bytes:
    """_type4 of colorants that all have recipes (the function as before the mixed case)."""
    n = len(recipes)
    ops: list[str] = []
    for j in range(4):
        terms = 0
        for i, r in enumerate(recipes):
            if r[j] == 0:
                continue
            depth = (n - 1 - i) + j + (1 if terms else 0)
            ops.append(f"{depth} index {r[j]:.5f} mul" + (" add" if terms else ""))
            terms += 1
        if not terms:
            ops.append("0")
        else:
            ops.append("dup 1 gt { pop 1 } if")
    ops.append(f"{n + 4} 4 roll" if n else "")       # the inks under the tints, then drop those
    ops += ["pop"] * n
    return ("{ " + " ".join(o for o in ops if o) + " }").encode()


def rewrite(src: str, dst: str, recipe_of: Callable[[str], tuple | None], output_icc: bytes | None,
            sample_alone: Callable | None = None) -> dict:
    """Write `dst`: `src` with every Separation/DeviceN whose colorants all have a recipe
    (`recipe_of(name)`: ink fractions, or None) printing it, and every cut colour removed
    from the print (docs/spot.md).  `output_icc`: the job's output profile (the recipes'
    space), or None (DeviceCMYK is the output).  `sample_alone(pdf, space, [i, ...])`:
    for a DeviceN mixing library colours with colorants in no library, each of those
    colorants' inks (an (S, 4) array at S even tints) as the space's alternate prints it
    alone; without it such a space keeps its alternate.  Returns counts for the log."""
    pikepdf = _pikepdf()
    stats = {"separation": 0, "devicen": 0, "devicen_mixed": 0, "cut_ops": 0}
    with pikepdf.open(src) as pdf:
        alt = pikepdf.Name.DeviceCMYK
        if output_icc:
            alt = pikepdf.Array([pikepdf.Name.ICCBased,
                                 pdf.make_indirect(pikepdf.Stream(pdf, output_icc, N=4,
                                                                  Alternate=pikepdf.Name.DeviceCMYK))])
        seen: set = set()
        done: set = set()
        for res in _page_resources(pdf):
            for cs in _spaces(res, seen):
                _recolour(pdf, cs, recipe_of, alt, stats, done, sample_alone)
        _remove_cut(pdf, stats)
        pdf.save(dst)
    return stats


def _base_spaces(cs) -> Iterator:
    """The Separation/DeviceN arrays inside a colour space (itself, or Indexed/Pattern's base)."""
    pikepdf = _pikepdf()
    if isinstance(cs, pikepdf.Array) and len(cs):
        head = _name(cs[0])
        if head in ("Separation", "DeviceN"):
            yield cs
        elif head in ("Indexed", "I", "Pattern") and len(cs) >= 2:
            yield from _base_spaces(cs[1])


def _recolour(pdf, cs, recipe_of, alt, stats: dict, done: set, sample_alone=None) -> None:
    pikepdf = _pikepdf()
    for arr in _base_spaces(cs):
        key = id(arr) if not arr.is_indirect else arr.objgen
        if key in done:
            continue
        done.add(key)
        head = _name(arr[0])
        names = [_name(arr[1])] if head == "Separation" else [_name(n) for n in arr[1]]
        recipes: list = []
        unknown: list[int] = []
        library = False
        for i, n in enumerate(names):
            if is_cut_name(n) or n == "None":
                recipes.append((0.0, 0.0, 0.0, 0.0))
            elif n.casefold() in PROCESS and head == "DeviceN":
                recipes.append(PROCESS[n.casefold()])
            else:
                r = recipe_of(n)
                if r is None:
                    unknown.append(i)
                    recipes.append(None)
                else:
                    library = True
                    recipes.append(tuple(float(v) for v in r))
        if unknown and head == "DeviceN" and library and sample_alone is not None:
            # a library colour beside colorants in no library (docs/spot.md "A DeviceN that
            # mixes"): the library colour by its recipe, each other colorant as the
            # document's alternate prints it alone
            for i, curve in sample_alone(pdf, arr, unknown).items():
                recipes[i] = [tuple(float(v) for v in row) for row in curve]
            stats["devicen_mixed"] += 1
        elif unknown:
            continue                        # the whole space through its alternate, as before
        if all(is_cut_name(n) or n == "None" for n in names):
            continue                    # a cut space: its painting is removed instead
        if head == "Separation":
            fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0],
                                    C1=[round(v, 5) for v in recipes[0]], N=1)
            stats["separation"] += 1
        else:
            fn = pdf.make_stream(_type4(recipes))
            fn.FunctionType = 4
            fn.Domain = pikepdf.Array([0, 1] * len(names))
            fn.Range = pikepdf.Array([0, 1] * 4)
            stats["devicen"] += 1
        arr[2] = alt
        arr[3] = fn


def _is_cut_space(cs) -> bool:
    kind, names = _cs_kind(cs)
    real = [n for n in names if n != "None"]
    return bool(kind) and bool(real) and all(is_cut_name(n) for n in real)


def _cut_names_of(resources) -> dict[str, bool]:
    """Resource name of each colour space -> is it a cut colour (once per stream: a cs/CS
    looked up each time cost two thirds of the edit)."""
    pikepdf = _pikepdf()
    d = resources.get("/ColorSpace") if isinstance(resources, pikepdf.Dictionary) else None
    if not isinstance(d, pikepdf.Dictionary):
        return {}
    return {str(k): _is_cut_space(v) for k, v in d.items()}


def _lookup_cs(cut_cs: dict[str, bool], operand) -> bool:
    """Is the colour space named by a cs/CS operand a cut colour?"""
    if isinstance(operand, _pikepdf().Array):
        return _is_cut_space(operand)
    return cut_cs.get(str(operand), False)


def _has_cut(resources) -> bool:
    return any(_is_cut_space(cs) for cs in _spaces(resources, set()))


# painting operators -> (paints fill, paints stroke); and what is left of each when one
# half is cut
_PAINT = {"S": (False, True), "s": (False, True), "f": (True, False), "F": (True, False),
          "f*": (True, False), "B": (True, True), "B*": (True, True), "b": (True, True),
          "b*": (True, True)}
_FILL_ONLY = {"B": "f", "B*": "f*", "b": "f", "b*": "f*"}
_STROKE_ONLY = {"B": "S", "B*": "S", "b": "s", "b*": "s"}
_TEXT_SHOW = ("Tj", "TJ", "'", '"')
# text render mode -> (fills, strokes)
_TR_PAINTS = {0: (True, False), 1: (False, True), 2: (True, True), 4: (True, False),
              5: (False, True), 6: (True, True)}


@dataclass
class _Gstate:
    """What the edit follows of the graphics state (pushed by q, popped by Q)."""
    fill_cut: bool = False
    stroke_cut: bool = False
    tr: int = 0
    alpha: tuple = (1.0, 1.0)       # ExtGState ca, CA


def _ins(operands, op: str):
    pikepdf = _pikepdf()
    return pikepdf.ContentStreamInstruction(list(operands), pikepdf.Operator(op))


def _alpha_state(resources, name, alpha: tuple) -> tuple:
    pikepdf = _pikepdf()
    d = resources.get("/ExtGState") if isinstance(resources, pikepdf.Dictionary) else None
    g = d.get(str(name)) if isinstance(d, pikepdf.Dictionary) else None
    if not isinstance(g, pikepdf.Dictionary):
        return alpha
    return (float(g.get("/ca", alpha[0])), float(g.get("/CA", alpha[1])))


def _alpha_gs(resources, alpha: tuple):
    """A `gs` instruction setting the fill and stroke alpha (ca, CA) (an ExtGState added to
    the resources)."""
    pikepdf = _pikepdf()
    if "/ExtGState" not in resources:
        resources.ExtGState = pikepdf.Dictionary()
    name = f"/WPspotA{alpha[0]:g}_{alpha[1]:g}".replace(".", "p")
    if name not in resources.ExtGState:
        resources.ExtGState[name] = pikepdf.Dictionary(Type=pikepdf.Name.ExtGState, ca=alpha[0], CA=alpha[1])
    return _ins([pikepdf.Name(name)], "gs")


def _edit_stream(instructions, resources, stats: dict):
    """The instructions with every painting in a cut colour removed."""
    pikepdf = _pikepdf()
    out = []
    st = _Gstate()
    stack: list[_Gstate] = []
    cut_cs = _cut_names_of(resources)
    xobjects = resources.get("/XObject") if isinstance(resources, pikepdf.Dictionary) else None
    shadings = resources.get("/Shading") if isinstance(resources, pikepdf.Dictionary) else None
    for ins in instructions:
        if isinstance(ins, pikepdf.ContentStreamInlineImage):
            out.append(ins)
            continue
        operands, op = ins.operands, str(ins.operator)
        if op == "q":
            stack.append(replace(st))
        elif op == "Q":
            if stack:
                st = stack.pop()
        elif op == "cs":
            st.fill_cut = _lookup_cs(cut_cs, operands[0]) if operands else False
        elif op == "CS":
            st.stroke_cut = _lookup_cs(cut_cs, operands[0]) if operands else False
        elif op in ("g", "rg", "k"):
            st.fill_cut = False
        elif op in ("G", "RG", "K"):
            st.stroke_cut = False
        elif op == "Tr" and operands:
            st.tr = int(operands[0])
        elif op == "gs" and operands:
            st.alpha = _alpha_state(resources, operands[0], st.alpha)
        elif op in _PAINT and (st.fill_cut or st.stroke_cut):
            fills, strokes = _PAINT[op]
            if (not fills or st.fill_cut) and (not strokes or st.stroke_cut):
                out.append(_ins([], "n"))
                stats["cut_ops"] += 1
                continue
            if fills and strokes:
                out.append(_ins([], _FILL_ONLY[op] if st.stroke_cut else _STROKE_ONLY[op]))
                stats["cut_ops"] += 1
                continue
        elif op in _TEXT_SHOW and (st.fill_cut or st.stroke_cut):
            fills, strokes = _TR_PAINTS.get(st.tr, (False, False))
            no_fill, no_stroke = fills and st.fill_cut, strokes and st.stroke_cut
            if no_fill or no_stroke:
                # the glyphs painted fully transparent (alpha 0): nothing printed, nothing
                # knocked out, the text advances.  Not render mode 3, whose text
                # Ghostscript 10.00 draws without advancing (what follows moved back);
                # not overprint, which a colour converted to the output profile ignores
                out.append(_alpha_gs(resources, (0.0 if no_fill else st.alpha[0],
                                                 0.0 if no_stroke else st.alpha[1])))
                out.append(ins)
                out.append(_alpha_gs(resources, st.alpha))
                stats["cut_ops"] += 1
                continue
        elif op == "Do" and operands and isinstance(xobjects, pikepdf.Dictionary) \
                and str(operands[0]) in xobjects:
            xo = xobjects[str(operands[0])]
            if _name(xo.get("/Subtype", "")) == "Image":
                mask = bool(xo.get("/ImageMask", False))
                if (mask and st.fill_cut) or ("/ColorSpace" in xo and _is_cut_space(xo.ColorSpace)):
                    stats["cut_ops"] += 1
                    continue
        elif op == "sh" and operands and isinstance(shadings, pikepdf.Dictionary) \
                and str(operands[0]) in shadings:
            sh = shadings[str(operands[0])]
            if "/ColorSpace" in sh and _is_cut_space(sh.ColorSpace):
                stats["cut_ops"] += 1
                continue
        out.append(ins)
    return out


def _remove_cut(pdf, stats: dict) -> None:
    """Every content stream (pages, forms, tiling patterns, annotation appearances) whose
    resources hold a cut colour space, edited."""
    pikepdf = _pikepdf()
    done: set = set()

    def edit(holder, resources, is_page: bool) -> None:
        if not isinstance(resources, pikepdf.Dictionary) or not _has_cut(resources):
            return
        before = stats["cut_ops"]
        ins = _edit_stream(pikepdf.parse_content_stream(holder), resources, stats)
        if stats["cut_ops"] != before:
            data = pikepdf.unparse_content_stream(ins)
            if is_page:
                holder.obj.Contents = pdf.make_stream(data)
            else:
                holder.write(data)
        for sub in ("/XObject", "/Pattern"):
            d = resources.get(sub)
            if not isinstance(d, pikepdf.Dictionary):
                continue
            for obj in d.values():
                if isinstance(obj, pikepdf.Stream) and "/Resources" in obj and obj.objgen not in done:
                    done.add(obj.objgen)
                    edit(obj, obj.Resources, False)

    for page in pdf.pages:
        edit(page, page.obj.get("/Resources"), True)
        for s in _appearances(page):
            if s.objgen not in done:
                done.add(s.objgen)
                edit(s, s.Resources, False)
