"""The viewer's multisampling choice (web/js/render.js's rendererName and msaaSamplesFor) in
Node.js: none on a software renderer, where every frame of the splats costs seconds, Cesium's
default on a GPU, and the page's ?msaa= over both."""

from __future__ import annotations

import shutil

import pytest

from tests.nodejs import run_web_module

pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")

SWIFTSHADER = ("ANGLE (Google, Vulkan 1.3.0 (SwiftShader Device (Subzero) (0x0000C0DE)), "
               "SwiftShader driver)")  # what Debian's headless chromium reports
GPU = "ANGLE (NVIDIA, NVIDIA GeForce RTX 3060 (0x00002503) Direct3D11 vs_5_0 ps_5_0, D3D11)"


def run_js(body: str, data) -> object:
    """Run `body` with web/js/render.js bound as R."""
    return run_web_module("render.js", "const R = M;\n" + body, data)


def test_software_renderers_draw_without_multisampling_and_gpus_keep_the_default():
    got = run_js("console.log(JSON.stringify(data.map(([p, r]) => R.msaaSamplesFor(p, r))));", [
        [None, SWIFTSHADER], [None, "llvmpipe (LLVM 15.0.6, 256 bits)"],
        [None, "Microsoft Basic Render Driver"], [None, GPU], [None, ""],
        ["keep", SWIFTSHADER], ["4", SWIFTSHADER], ["1", GPU], ["8", GPU],
        ["3", SWIFTSHADER], ["3", GPU], ["many", GPU],
    ])
    # an unusable ?msaa= (3, "many") is ignored: the renderer decides
    assert got == [1, 1, 1, None, None, None, 4, 1, 8, 1, None, None]


def test_renderer_name_is_the_unmasked_one_where_the_browser_tells_it():
    got = run_js("""
      const gl = (ext, masked) => ({ RENDERER: 7937,
        getExtension: (name) => (ext && name === "WEBGL_debug_renderer_info"
          ? { UNMASKED_RENDERER_WEBGL: 37446 } : null),
        getParameter: (k) => (k === 37446 ? data : k === 7937 ? masked : null) });
      console.log(JSON.stringify([R.rendererName(gl(true, "WebKit WebGL")),
        R.rendererName(gl(false, "WebKit WebGL")), R.rendererName(null)]));""", SWIFTSHADER)
    assert got == [SWIFTSHADER, "WebKit WebGL", ""]
