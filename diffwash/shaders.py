"""The real-time shaders: GLSL 3.30, WebGL2 and three.js (ShaderMaterial) sources generated from the model (`diffwash._glsl`).

`shader_sources(target, shading, colour=...)` gives a vertex and a fragment shader;
`functions_source(target)` the model as a library to include in an engine's own shaders;
`uniform_values(scene)` the values a host program sets. docs/realtime.md describes them.
"""

from ._glsl import COLOUR_PATHS as COLOUR_PATHS
from ._glsl import SHADING_MODES as SHADING_MODES
from ._glsl import TARGETS as TARGETS
from ._glsl import functions_source as functions_source
from ._glsl import shader_file_names as shader_file_names
from ._glsl import shader_sources as shader_sources
from ._glsl import uniform_values as uniform_values
