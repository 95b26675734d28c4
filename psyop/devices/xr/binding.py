"""The OpenGL graphics binding between psyop's moderngl context and an OpenXR session.

An OpenXR session renders with the application's own OpenGL context; ``xrCreateSession`` is
handed that context in one of two Linux bindings:

- ``egl``: ``XrGraphicsBindingEGLMNDX`` (``XR_MNDX_egl_enable``), a headless EGL context. Monado
  offers it; it needs no window system.
- ``xlib``: ``XrGraphicsBindingOpenGLXlibKHR`` (core ``XR_KHR_opengl_enable``), a GLX context on
  an X display (``DISPLAY``). SteamVR on Linux offers only this one.

``--display openxr`` chooses ``egl`` when the runtime offers it, else ``xlib`` when an X display is
there; ``--display openxr:egl`` / ``openxr:xlib`` force one. Windows (WGL) and Wayland bindings
are not implemented. Both bindings are tested against Monado (``tests/devices/xr``: ``xlib`` under
Xvfb); SteamVR itself could not be run here.

The handles come from the context current on this thread, through the system's libEGL / libGL and
libX11 (ctypes): the context moderngl creates is the one the runtime renders into.
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    import moderngl

GraphicsApi = Literal["egl", "xlib"]
#: a pyopenxr struct, handle or enum: pyopenxr ships no type stubs, so its ctypes objects are untyped
XrObject = Any  # Any: pyopenxr is untyped (above)

GRAPHICS_APIS: tuple[GraphicsApi, ...] = ("egl", "xlib")

EGL_EXTENSION = "XR_MNDX_egl_enable"
OPENGL_EXTENSION = "XR_KHR_opengl_enable"


@dataclass(frozen=True)
class BindingChoice:
    """The binding chosen for a runtime, and the instance extensions it needs."""

    api: GraphicsApi
    extensions: tuple[str, ...]


def choose_binding(available: set[str] | frozenset[str], requested: str = "auto",
                   x_display: str | None = None) -> BindingChoice | str:
    """The binding for a runtime offering the instance extensions ``available``, or why none fits.

    ``requested`` is ``"auto"``, ``"egl"`` or ``"xlib"``; ``x_display`` is ``$DISPLAY`` (``None``:
    read it). A string result is the reason no binding fits (for a one-line error).

    Examples
    --------
    >>> choose_binding({"XR_KHR_opengl_enable", "XR_MNDX_egl_enable"}, x_display="")
    BindingChoice(api='egl', extensions=('XR_KHR_opengl_enable', 'XR_MNDX_egl_enable'))
    >>> choose_binding({"XR_KHR_opengl_enable"}, x_display=":0")
    BindingChoice(api='xlib', extensions=('XR_KHR_opengl_enable',))
    >>> choose_binding({"XR_KHR_opengl_enable"}, x_display="")
    'the runtime offers OpenGL only through GLX/Xlib (no XR_MNDX_egl_enable) and DISPLAY is not set: run on the X display the headset runtime uses'
    """
    x_display = os.environ.get("DISPLAY", "") if x_display is None else x_display
    if OPENGL_EXTENSION not in available:
        return f"the runtime offers no OpenGL binding ({OPENGL_EXTENSION}); psyop renders with OpenGL only"
    egl_ok = EGL_EXTENSION in available
    if requested == "egl":
        return (BindingChoice("egl", (OPENGL_EXTENSION, EGL_EXTENSION)) if egl_ok else
                f"--display openxr:egl: the runtime does not offer {EGL_EXTENSION}; use openxr:xlib")
    if requested == "xlib":
        return (BindingChoice("xlib", (OPENGL_EXTENSION,)) if x_display else
                "--display openxr:xlib needs an X display and DISPLAY is not set")
    if requested != "auto":
        return f"--display openxr:{requested}: expected one of auto, {', '.join(GRAPHICS_APIS)}"
    if egl_ok:
        return BindingChoice("egl", (OPENGL_EXTENSION, EGL_EXTENSION))
    if x_display:
        return BindingChoice("xlib", (OPENGL_EXTENSION,))
    return (f"the runtime offers OpenGL only through GLX/Xlib (no {EGL_EXTENSION}) and DISPLAY is not set: "
            "run on the X display the headset runtime uses")


def create_context(api: GraphicsApi) -> moderngl.Context:
    """A standalone moderngl context of the kind ``api`` binds (made current on this thread)."""
    import moderngl

    if api == "egl":
        # moderngl-stubs 5.13 type each keyword of **settings as a dict (it is one setting's value)
        return moderngl.create_standalone_context(backend="egl")  # type: ignore[arg-type]
    return moderngl.create_standalone_context()


@dataclass
class GraphicsBinding:
    """The binding structure handed to ``xrCreateSession`` and the libraries it came from (kept
    alive with it: the runtime keeps the pointers)."""

    api: GraphicsApi
    struct: XrObject
    libraries: tuple[XrObject, ...]

    def pointer(self) -> ctypes.c_void_p:
        return ctypes.cast(ctypes.pointer(self.struct), ctypes.c_void_p)


def current_binding(xr: ModuleType, api: GraphicsApi) -> GraphicsBinding | str:
    """The ``api`` binding of the OpenGL context current on this thread, or why it cannot be made."""
    return _egl_binding(xr) if api == "egl" else _xlib_binding(xr)


def _egl_binding(xr: ModuleType) -> GraphicsBinding | str:
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglGetCurrentContext.restype = ctypes.c_void_p
    egl.eglQueryContext.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    egl.eglChooseConfig.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_void_p),
                                    ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    dpy, ectx = egl.eglGetCurrentDisplay(), egl.eglGetCurrentContext()
    config_id = ctypes.c_int()
    egl.eglQueryContext(dpy, ectx, 0x3028, ctypes.byref(config_id))  # EGL_CONFIG_ID
    attrs = (ctypes.c_int * 3)(0x3028, config_id.value, 0x3038)  # EGL_CONFIG_ID, id, EGL_NONE
    config, n = ctypes.c_void_p(), ctypes.c_int()
    egl.eglChooseConfig(dpy, attrs, ctypes.byref(config), 1, ctypes.byref(n))
    if not (dpy and ectx and n.value == 1):
        return "psyop's OpenGL context is not a current EGL context (no EGL display, context or config)"
    struct = xr.GraphicsBindingEGLMNDX(get_proc_address=ctypes.cast(egl.eglGetProcAddress,
                                                                    xr.PFN_xrEglGetProcAddressMNDX))
    fields = dict(xr.GraphicsBindingEGLMNDX._fields_)
    struct.display = ctypes.cast(ctypes.c_void_p(dpy), fields["display"])
    struct.config = ctypes.cast(ctypes.c_void_p(config.value), fields["config"])
    struct.context = ctypes.cast(ctypes.c_void_p(ectx), fields["context"])
    return GraphicsBinding("egl", struct, (egl,))


class _XWindowAttributes(ctypes.Structure):
    """The head of Xlib's XWindowAttributes (up to ``visual``), padded past its end."""

    _fields_ = [("x", ctypes.c_int), ("y", ctypes.c_int), ("width", ctypes.c_int), ("height", ctypes.c_int),
                ("border_width", ctypes.c_int), ("depth", ctypes.c_int), ("visual", ctypes.c_void_p),
                ("rest", ctypes.c_char * 256)]


_GLX_SCREEN = 0x800C
_GLX_FBCONFIG_ID = 0x8013


def _xlib_binding(xr: ModuleType) -> GraphicsBinding | str:
    gl = ctypes.CDLL("libGL.so.1")
    x11 = ctypes.CDLL("libX11.so.6")
    gl.glXGetCurrentDisplay.restype = ctypes.c_void_p
    gl.glXGetCurrentContext.restype = ctypes.c_void_p
    gl.glXGetCurrentDrawable.restype = ctypes.c_ulong
    gl.glXQueryContext.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    gl.glXGetFBConfigs.restype = ctypes.POINTER(ctypes.c_void_p)
    gl.glXGetFBConfigs.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    gl.glXGetFBConfigAttrib.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    x11.XGetWindowAttributes.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.POINTER(_XWindowAttributes)]
    x11.XVisualIDFromVisual.argtypes = [ctypes.c_void_p]
    x11.XVisualIDFromVisual.restype = ctypes.c_ulong
    x11.XFree.argtypes = [ctypes.c_void_p]
    dpy, glx_ctx, drawable = gl.glXGetCurrentDisplay(), gl.glXGetCurrentContext(), gl.glXGetCurrentDrawable()
    if not (dpy and glx_ctx and drawable):
        return "psyop's OpenGL context is not a current GLX context (no X display, context or drawable)"
    fbconfig_id, screen = ctypes.c_int(), ctypes.c_int()
    gl.glXQueryContext(dpy, glx_ctx, _GLX_FBCONFIG_ID, ctypes.byref(fbconfig_id))
    gl.glXQueryContext(dpy, glx_ctx, _GLX_SCREEN, ctypes.byref(screen))
    # glXChooseFBConfig(GLX_FBCONFIG_ID) finds nothing on Mesa; look the context's config up by its id
    n = ctypes.c_int()
    configs = gl.glXGetFBConfigs(dpy, screen.value, ctypes.byref(n))
    fbconfig = None
    for i in range(n.value):
        value = ctypes.c_int()
        gl.glXGetFBConfigAttrib(dpy, configs[i], _GLX_FBCONFIG_ID, ctypes.byref(value))
        if value.value == fbconfig_id.value:
            fbconfig = configs[i]
            break
    if configs:
        x11.XFree(configs)
    attributes = _XWindowAttributes()
    if fbconfig is None or not x11.XGetWindowAttributes(dpy, drawable, ctypes.byref(attributes)):
        return f"the GLX context's framebuffer config ({fbconfig_id.value}) or its drawable's visual was not found"
    visualid = int(x11.XVisualIDFromVisual(attributes.visual))  # the drawable's visual, which the context draws with
    from xr.platform.linux import GraphicsBindingOpenGLXlibKHR

    fields = dict(GraphicsBindingOpenGLXlibKHR._fields_)
    struct = GraphicsBindingOpenGLXlibKHR()
    struct.x_display = ctypes.cast(ctypes.c_void_p(dpy), fields["x_display"])
    struct.visualid = visualid
    struct.glx_fbconfig = ctypes.cast(ctypes.c_void_p(fbconfig), fields["glx_fbconfig"])
    struct.glx_drawable = drawable
    struct.glx_context = ctypes.cast(ctypes.c_void_p(glx_ctx), fields["glx_context"])
    return GraphicsBinding("xlib", struct, (gl, x11))


__all__ = ["BindingChoice", "GRAPHICS_APIS", "GraphicsApi", "GraphicsBinding", "choose_binding", "create_context",
           "current_binding"]
