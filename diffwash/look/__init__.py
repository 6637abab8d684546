"""The watercolour look (issue 13): paper, edges, unevenness, brush strokes, hatching, shadows, pigment mixes.

The seed's future work, as array operators in JAX with a GLSL twin of each,
generated here from the same constants (docs/watercolour.md):

- `_textures`: the screen-space tile (paper height and shading, turbulence and
  dispersion noises), procedural or from an image;
- `_paper`: granulation and staining (Curtis et al. 1997), density,
  unevenness (Bousseau et al. 2006), paper shading;
- `_edges`: edge darkening (a separable, fixed-radius blur at reduced
  resolution);
- `_strokes`: the brush-stroke layer, LIC of solid noise along principal
  curvature directions (Lum and Ma 2001), a per-vertex attribute;
- `_hatching`: a tonal art map (Praun et al. 2001) for a pen-and-wash unlit
  glaze;
- `_shadow`: a shadow map and percentage-closer lookups for self-shadowing;
- `_mix`: pigment mixes across a surface and their 3D LUT;
- `_look`: the `Look` parameters and the pipeline (`surface_terms`,
  `image_terms`, `compose`) with its GLSL passes.
"""

from ._edges import EDGE_DOWNSAMPLE as EDGE_DOWNSAMPLE
from ._edges import EDGE_GRID as EDGE_GRID
from ._edges import EDGE_RADIUS as EDGE_RADIUS
from ._edges import blur as blur
from ._edges import downsample as downsample
from ._edges import edge_darkening as edge_darkening
from ._edges import edge_downsample as edge_downsample
from ._edges import gaussian_weights as gaussian_weights
from ._edges import gaussian_weights_np as gaussian_weights_np
from ._edges import glsl_edge_darkening as glsl_edge_darkening
from ._edges import glsl_edge_passes as glsl_edge_passes
from ._edges import local_mean as local_mean
from ._edges import upsample as upsample
from ._hatching import TAM_LEVELS as TAM_LEVELS
from ._hatching import TONES as TONES
from ._hatching import glsl_hatching as glsl_hatching
from ._hatching import hatch_ink as hatch_ink
from ._hatching import hatch_lod as hatch_lod
from ._hatching import hatch_samples as hatch_samples
from ._hatching import hatch_ink_at as hatch_ink_at
from ._hatching import pack_tam as pack_tam
from ._hatching import PackedMap as PackedMap
from ._hatching import sample_tam as sample_tam
from ._hatching import tonal_art_map as tonal_art_map
from ._hatching import tam_atlas as tam_atlas
from ._hatching import tone_weights as tone_weights
from ._look import DEFAULT_LOOK as DEFAULT_LOOK
from ._look import OFF as OFF
from ._look import Look as Look
from ._look import Pigments as Pigments
from ._look import compose as compose
from ._look import glsl_final_pass as glsl_final_pass
from ._look import glsl_surface as glsl_surface
from ._look import image_terms as image_terms
from ._look import look_uniforms as look_uniforms
from ._look import surface_terms as surface_terms
from ._mix import bake_mix_lut as bake_mix_lut
from ._mix import blended_pair_error as blended_pair_error
from ._mix import check_mix_map as check_mix_map
from ._mix import glaze_mix as glaze_mix
from ._mix import glsl_mix_lut as glsl_mix_lut
from ._mix import lookup_mix_lut as lookup_mix_lut
from ._mix import mix_along_axis as mix_along_axis
from ._mix import mix_lut_error as mix_lut_error
from ._paper import DENSITY_REFERENCE as DENSITY_REFERENCE
from ._paper import PigmentLook as PigmentLook
from ._paper import deposit as deposit
from ._paper import glsl_paper as glsl_paper
from ._paper import paper_shading as paper_shading
from ._paper import pigment_factor as pigment_factor
from ._paper import pigment_look as pigment_look
from ._paper import unevenness_factor as unevenness_factor
from ._shadow import SHADOW_MAP_SIZE as SHADOW_MAP_SIZE
from ._shadow import SHADOW_TAPS as SHADOW_TAPS
from ._shadow import glsl_depth_pass as glsl_depth_pass
from ._shadow import glsl_shadow as glsl_shadow
from ._shadow import light_clip as light_clip
from ._shadow import light_depth as light_depth
from ._shadow import light_view_projection as light_view_projection
from ._shadow import normal_offset as normal_offset
from ._shadow import shadow as shadow
from ._strokes import glsl_strokes as glsl_strokes
from ._strokes import principal_directions as principal_directions
from ._strokes import solid_noise as solid_noise
from ._strokes import stroke_factor as stroke_factor
from ._strokes import stroke_field as stroke_field
from ._textures import CHANNELS as CHANNELS
from ._textures import ScreenTextures as ScreenTextures
from ._textures import band_noise as band_noise
from ._textures import paper_from_image as paper_from_image
from ._textures import paper_shade as paper_shade
from ._textures import procedural_paper as procedural_paper
from ._textures import screen_textures as screen_textures
from ._textures import tile as tile
