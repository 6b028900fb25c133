//! The page and everything it loads, built into the binary: the studio works
//! offline and fetches nothing at run time. three.js (MIT, its LICENSE
//! beside it) is vendored from npm by `scripts/vendor-three.sh`.

/// The page. It holds no token: its requests carry the studio's cookie,
/// which its scripts cannot read (HttpOnly).
pub fn page() -> &'static str {
    include_str!("page/index.html")
}

/// The page's inline scripts (its import map), as the Content-Security-Policy
/// hashes them: the text between the tags.
pub fn inline_scripts() -> Vec<&'static str> {
    let mut out = Vec::new();
    let mut rest = page();
    while let Some(at) = rest.find("<script") {
        let tag_end = at + rest[at..].find('>').map_or(rest.len() - at, |e| e + 1);
        let tag = &rest[at..tag_end];
        let close = rest[tag_end..].find("</script>").map_or(rest.len(), |c| tag_end + c);
        if !tag.contains(" src=") {
            out.push(&rest[tag_end..close]);
        }
        rest = &rest[close..];
        if let Some(r) = rest.strip_prefix("</script>") {
            rest = r;
        } else {
            break;
        }
    }
    out
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
