"""Make a synthetic photo of a pigment's swatch card (patches of 1, 2, 3... coats over paper and over a black ink
band) with a camera's faults (exposure and white-balance error, vignetting and uneven light, paper grain, noise,
blur, JPEG), and its layout file beside it: what diffwash fit-swatch reads. The Python equivalent is
diffwash.swatchcard.make_swatch_card.

With `--library LIB.json --patches "P1:1,P4:2,P1+P4:1+1"` the card paints a mixable library's pigments, alone
or mixed in one layer (diffwash.swatchcard.make_mixture_card): a card fit-swatch fits into a library.
"""

from __future__ import annotations

import re
from pathlib import Path

import diffwash

from .. import DiffwashError
from .. import io as dio

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("pigment", metavar="PIGMENT", nargs="?",
                   help="a pigment name from the library, or a pigment file (or --library and --patches)")  # fmt: skip
    p.add_argument("-o", "--output", required=True, metavar="PHOTO", help="the photo to write: .jpg, .jpeg or .png")
    p.add_argument("--library", metavar="LIB.json",
                   help="paint a mixable library's pigments (diffwash fit-swatch --table writes one) instead of PIGMENT")  # fmt: skip
    p.add_argument("--patches", metavar="LIST",
                   help='with --library: the patches, PIGMENTS:COATS separated by commas, e.g. "P1:1,P4:2,P1+P4:1+1,P1/P4:1/1" (/: a glaze stack, bottom layer first)')  # fmt: skip
    p.add_argument("--amount-per-coat", type=float, metavar="A",
                   help="with --library: the amount of one coat (default: the library's reference amount)")  # fmt: skip
    p.add_argument("--layout", metavar="JSON", help="where to write the layout (default: beside the photo, .json)")
    p.add_argument("--coats", default="1,2,3,4", metavar="LIST",
                   help="coat counts of the patches (default: %(default)s)")  # fmt: skip
    p.add_argument("--no-black", action="store_true", help="no black ink band (patches over paper only)")
    p.add_argument("--ideal", action="store_true", help="a perfect camera: no falloff, noise, blur or grain")
    p.add_argument("--bits", type=int, choices=(8, 16), default=8, help="PNG bits per channel (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")


def run(args) -> int:
    out = Path(args.output)
    dio.image_format_for(out, bits=args.bits, field="--output")
    layout = Path(args.layout) if args.layout else out.with_suffix(".json")
    if not 0 <= args.seed < 2**32:  # as a scene's seeds: what every random generator diffwash uses takes
        raise DiffwashError(f"must be a whole number >= 0 and < 2^32, got {args.seed}", field="--seed")
    if args.amount_per_coat is not None:
        dio.check_float32(args.amount_per_coat, field="--amount-per-coat")
    if args.library is not None or args.patches is not None:
        return _mixture_card(args, out, layout)
    if args.pigment is None:
        raise DiffwashError("give a pigment (or --library and --patches)", field="PIGMENT")
    if args.amount_per_coat is not None:
        raise DiffwashError("is for a card of a library's pigments (--library, --patches)", field="--amount-per-coat")
    pigment_file = [args.pigment] if Path(args.pigment).is_file() else []
    dio.refuse_overwriting_inputs({"--output": out, "--layout": layout}, pigment_file)
    try:
        coats = [float(c) for c in args.coats.split(",")]
    except ValueError:
        raise DiffwashError(f"must be comma-separated numbers, got {args.coats!r}", field="--coats") from None
    if not coats or any(not (0 < c < 1e3) for c in coats):
        raise DiffwashError(f"must be numbers of coats > 0, got {args.coats!r}", field="--coats")
    pigment = diffwash.pigments.load(args.pigment)
    effects = diffwash.swatchcard.IDEAL if args.ideal else diffwash.swatchcard.CameraEffects()
    card = diffwash.swatchcard.make_swatch_card(pigment, coats=coats, black=not args.no_black, effects=effects, seed=args.seed)
    card.layout["name"] = pigment.name
    diffwash.swatchcard.save_swatch_card(card, out, layout, bits=args.bits)
    h, w = card.photo.shape[:2]
    print(f"wrote {out} ({w}x{h}, {pigment.name} at {', '.join(f'{c:g}' for c in coats)} coats"
          f"{'' if args.no_black else ' over paper and black'}) and {layout}")  # fmt: skip
    return 0


def _mixture_card(args, out: Path, layout: Path) -> int:
    """`--library LIB.json --patches LIST`: a card of the library's pigments, alone or mixed."""
    if args.pigment is not None:
        raise DiffwashError(f"give either a pigment or --library, not both (got {args.pigment!r})", field="PIGMENT")
    if args.library is None or args.patches is None:
        raise DiffwashError("--library and --patches go together", field="--library" if args.library is None else "--patches")
    if args.coats != "1,2,3,4":
        raise DiffwashError("give each patch's coats in --patches (PIGMENTS:COATS) instead", field="--coats")
    dio.refuse_overwriting_inputs({"--output": out, "--layout": layout}, [args.library])
    patches = parse_patches(args.patches)
    lib = diffwash.library.load_library(args.library)
    known = {n.lower() for n in lib.names}
    unknown = sorted({n for names, _ in patches for n in re.split(r"[+/]", names) if n.lower() not in known})
    if unknown:
        raise DiffwashError(f"{', '.join(unknown)} not in the library (it has {', '.join(lib.names)})", field="--patches")
    effects = diffwash.swatchcard.IDEAL if args.ideal else diffwash.swatchcard.CameraEffects()
    try:
        card = diffwash.swatchcard.make_mixture_card(lib, patches, amount_per_coat=args.amount_per_coat, black=not args.no_black,
                                            effects=effects, seed=args.seed)  # fmt: skip
    except ValueError as e:
        field = "--amount-per-coat" if "amount_per_coat" in str(e) else "--seed" if "seed" in str(e) else "--patches"
        raise DiffwashError(str(e).replace("amount_per_coat ", "").replace("seed ", ""), field=field) from None
    diffwash.swatchcard.save_swatch_card(card, out, layout, bits=args.bits)
    h, w = card.photo.shape[:2]
    print(f"wrote {out} ({w}x{h}, {len(patches)} patches of {Path(args.library).name}"
          f"{'' if args.no_black else ' over paper and black'}) and {layout}")  # fmt: skip
    return 0


def parse_patches(text: str) -> list[tuple[str, str]]:
    """`"P1:1,P1+P4:1+2,P1/P4:1/2"` -> `[("P1", "1"), ("P1+P4", "1+2"), ("P1/P4", "1/2")]`: each patch's pigments
    and coats (one per pigment; `/` between the layers of a glaze stack, bottom first)."""
    patches = []
    for i, item in enumerate(text.split(",")):
        names, sep, coats = item.strip().rpartition(":")
        layers, groups = names.split("/"), coats.split("/")
        if not sep or len(layers) != len(groups):
            raise DiffwashError(f"patch {i + 1} must be PIGMENTS:COATS with a coat count per pigment (e.g. P1+P4:1+2, "
                                f"or P1/P4:1/2 for a glaze stack), got {item.strip()!r}", field="--patches")  # fmt: skip
        parts = [_layer_patch(i, item, n, c) for n, c in zip(layers, groups)]
        patches.append(("/".join(n for n, _ in parts), "/".join(c for _, c in parts)))
    return patches


def _layer_patch(i: int, item: str, names: str, coats: str) -> tuple[str, str]:
    """One layer of a `--patches` item: its `+`-joined names and coats, checked."""
    names = "+".join(" ".join(n.split()) for n in names.split("+"))
    counts = coats.strip().split("+")
    if not names or any(not n for n in names.split("+")) or len(counts) != len(names.split("+")):
        raise DiffwashError(f"patch {i + 1} must be PIGMENTS:COATS with a coat count per pigment (e.g. P1+P4:1+2, "
                            f"or P1/P4:1/2 for a glaze stack), got {item.strip()!r}", field="--patches")  # fmt: skip
    try:
        values = [float(c) for c in counts]
    except ValueError:
        raise DiffwashError(f"patch {i + 1}: coats must be numbers, got {coats.strip()!r}", field="--patches") from None
    if any(not (0 <= v < 1e3) for v in values) or sum(values) <= 0:
        raise DiffwashError(f"patch {i + 1}: coats must be >= 0 and > 0 in all (in each layer), got {coats.strip()!r}",
                            field="--patches")  # fmt: skip
    return names, "+".join(f"{v:g}" for v in values)
