"""Make a synthetic photo of a pigment's swatch card (patches of 1, 2, 3... coats over paper and over a black ink
band) with a camera's faults (exposure and white-balance error, vignetting and uneven light, paper grain, noise,
blur, JPEG), and its layout file beside it: what diffwash fit-swatch reads. The Python equivalent is
diffwash.swatchcard.make_swatch_card.
"""

from __future__ import annotations

from pathlib import Path

from .. import DiffwashError, pigments, swatchcard
from .. import io as dio

NAME = "swatch-card"
HELP = "make a synthetic swatch-card photo and its layout (for fit-swatch)"
USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("pigment", metavar="PIGMENT", help="a pigment name from the library, or a pigment file")
    p.add_argument("-o", "--output", required=True, metavar="PHOTO", help="the photo to write: .jpg, .jpeg or .png")
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
    pigment_file = [args.pigment] if Path(args.pigment).is_file() else []
    dio.refuse_overwriting_inputs({"--output": out, "--layout": layout}, pigment_file)
    try:
        coats = [float(c) for c in args.coats.split(",")]
    except ValueError:
        raise DiffwashError(f"must be comma-separated numbers, got {args.coats!r}", field="--coats") from None
    if not coats or any(not (0 < c < 1e3) for c in coats):
        raise DiffwashError(f"must be numbers of coats > 0, got {args.coats!r}", field="--coats")
    pigment = pigments.load(args.pigment)
    effects = swatchcard.IDEAL if args.ideal else swatchcard.CameraEffects()
    card = swatchcard.make_swatch_card(pigment, coats=coats, black=not args.no_black, effects=effects, seed=args.seed)
    card.layout["name"] = pigment.name
    swatchcard.save_swatch_card(card, out, layout, bits=args.bits)
    h, w = card.photo.shape[:2]
    print(f"wrote {out} ({w}x{h}, {pigment.name} at {', '.join(f'{c:g}' for c in coats)} coats"
          f"{'' if args.no_black else ' over paper and black'}) and {layout}")  # fmt: skip
    return 0
