"""Preview pictures: a scene's frame ray-cast on the device, colliding objects in colour, written as PNG or
an animated GIF.

>>> from warp_ccd.preview import render_frame, save_preview
>>> save_preview(render_frame(scene, pipe.detect()), "preview.png")
"""

from ._src.preview import PREVIEW_EXTENSIONS, PreviewRenderer, render_frame, save_preview

__all__ = ["PREVIEW_EXTENSIONS", "PreviewRenderer", "render_frame", "save_preview"]
