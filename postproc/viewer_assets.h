// The 3D view's scripts, compiled in (postproc/embed_js.cmake): three.js and its OrbitControls from
// Debian's libjs-three (r111, non-module builds; empty when the build did not find them), the error
// hooks and the page's own code (postproc/viewer_guard.js, postproc/viewer_page.js).
#pragma once
#include <string_view>

namespace flankcam {

[[nodiscard]] std::string_view viewer_three_js();
[[nodiscard]] std::string_view viewer_orbit_js();
[[nodiscard]] std::string_view viewer_guard_js();
[[nodiscard]] std::string_view viewer_page_js();

}  // namespace flankcam
