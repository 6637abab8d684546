"""Preview a scene in OpenGL through the exported shaders and a baked LUT.

This is the real-time path as an engine would run it: the `glsl330` shaders
that `diffwash export` writes, the LUT as a linearly filtered texture, the mesh
in vertex buffers, drawn with moderngl. `render` draws headless through EGL
(Mesa's llvmpipe on a machine without a GPU); `show` opens a window (needs a
display and the `glfw` package). It is also how the tests hold the real-time
path against `diffwash.render`.
"""

from ._preview import Preview as Preview
from ._preview import can_show as can_show
from ._preview import create_context as create_context
from ._preview import has_display as has_display
from ._preview import render as render
from ._preview import renderer_name as renderer_name
from ._window import show as show

__all__ = ["Preview", "create_context", "render", "show", "has_display", "can_show", "renderer_name"]
