//! The page and everything it loads, built into the binary: the studio works
//! offline and fetches nothing at run time. three.js (MIT, its LICENSE
//! beside it) is vendored from npm by `scripts/vendor-three.sh`.

/// The page, with the session token for its requests.
pub fn page(token: &str) -> String {
    include_str!("page/index.html").replace("{{TOKEN}}", token)
}

/// An asset by name: its content type and bytes.
pub fn asset(name: &str) -> Option<(&'static str, &'static [u8])> {
    const JS: &str = "text/javascript; charset=utf-8";
    Some(match name {
        "studio.js" => (JS, include_bytes!("page/studio.js")),
        "studio.css" => ("text/css; charset=utf-8", include_bytes!("page/studio.css")),
        "three.module.js" => (JS, include_bytes!("page/vendor/three/three.module.js")),
        "three.core.js" => (JS, include_bytes!("page/vendor/three/three.core.js")),
        "OrbitControls.js" => (JS, include_bytes!("page/vendor/three/OrbitControls.js")),
        "PLYLoader.js" => (JS, include_bytes!("page/vendor/three/PLYLoader.js")),
        "three-LICENSE.txt" => ("text/plain; charset=utf-8", include_bytes!("page/vendor/three/LICENSE")),
        _ => return None,
    })
}
