"""Files: JSON with located errors, images with size limits, and writes that are never half done.

What the command line uses to read and write, for tools built on diffwash: every writer writes to
a temporary name in the destination folder and renames it into place (a full disk or a crash leaves
nothing half-written); images are read as displayed (EXIF orientation) after their pixel count is
checked from the header; only regular files within a size limit are read (a named pipe, a device or a
folder is refused in one line, before anything blocks or fills memory); outputs that would overwrite inputs are refused; extensions name formats.
Errors are one-line `DiffwashError`s naming the file and the field.
"""

from ._io import FLOAT32_MAX as FLOAT32_MAX
from ._io import FILE_BYTES_ENV as FILE_BYTES_ENV
from ._io import IMAGE_FORMATS as IMAGE_FORMATS
from ._io import MAX_FILE_BYTES as MAX_FILE_BYTES
from ._io import MAX_IMAGE_PIXELS as MAX_IMAGE_PIXELS
from ._io import PIXELS_ENV as PIXELS_ENV
from ._io import atomic_folder as atomic_folder
from ._io import atomic_path as atomic_path
from ._io import atomic_paths as atomic_paths
from ._io import check_float32 as check_float32
from ._io import check_input_file as check_input_file
from ._io import image_format_for as image_format_for
from ._io import image_pixel_limit as image_pixel_limit
from ._io import max_file_bytes as max_file_bytes
from ._io import max_image_pixels as max_image_pixels
from ._io import open_input as open_input
from ._io import read_image as read_image
from ._io import read_json as read_json
from ._io import refuse_overwriting_inputs as refuse_overwriting_inputs
from ._io import save_figure as save_figure
from ._io import to_uint as to_uint
from ._io import write_image as write_image
from ._io import write_json as write_json
from ._io import write_png as write_png
from ._pigment_files import read_pigments as read_pigments
