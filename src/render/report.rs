//! `report.html`: one static, self-contained page per run (images inlined as
//! PNG data URIs, no network, no external files), so that a run folder can be
//! mailed, archived or opened from a render farm's web view as it is.
//!
//! The page carries one small inline script that only checks itself: after
//! loading it counts the images that decoded and writes the count into
//! `<body data-images-loaded="K/N">`, which a headless browser's dump of the
//! DOM shows (the interop test reads it).

use std::fmt::Write;

use base64::Engine;

/// Everything the page shows, gathered by the pipeline from a run folder.
#[derive(Clone, Debug, Default)]
pub struct ReportInputs {
    pub title: String,
    /// The contact sheet PNG (exemplar and variants from one camera).
    pub contact_sheet: Option<Vec<u8>>,
    /// `eval`'s table as text (fixed-width columns), and its JSON file name.
    pub eval_table: Option<String>,
    /// Per variant: its name and a preview PNG (the mesh, else the finest level).
    pub variants: Vec<(String, Vec<u8>)>,
    /// Per level: the training loss plot PNG.
    pub loss_plots: Vec<(usize, Vec<u8>)>,
    /// (what, seconds), in pipeline order.
    pub timings: Vec<(String, f64)>,
    /// The resolved configuration (TOML) and its digest.
    pub config_toml: String,
    pub config_digest: String,
}

fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            c => s.push(c),
        }
    }
    s
}

fn img(png: &[u8], alt: &str, class: &str) -> String {
    format!(
        "<img class=\"{class}\" alt=\"{}\" src=\"data:image/png;base64,{}\">",
        escape(alt),
        base64::engine::general_purpose::STANDARD.encode(png)
    )
}

const STYLE: &str = "body{font-family:sans-serif;margin:2em;max-width:1400px;color:#222}\
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:2em;border-bottom:1px solid #ccc}\
pre{background:#f6f6f6;padding:1em;overflow-x:auto;font-size:12px}\
.sheet{max-width:100%}.grid{display:flex;flex-wrap:wrap;gap:12px}\
figure{margin:0}figure img{width:256px;border:1px solid #ddd}figcaption{font-size:12px;text-align:center}\
.loss{width:640px;border:1px solid #ddd}table{border-collapse:collapse}\
td,th{padding:2px 12px;text-align:right;border-bottom:1px solid #eee}td:first-child,th:first-child{text-align:left}";

/// Checks that every image decoded; see the module comment.
const SELF_CHECK: &str = "window.addEventListener('load',function(){var i=document.images,k=0;\
for(var j=0;j<i.length;j++){if(i[j].complete&&i[j].naturalWidth>0)k++;}\
document.body.setAttribute('data-images-loaded',k+'/'+i.length);});";

/// The page.
pub fn html(r: &ReportInputs) -> String {
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style>\
         <script>{SELF_CHECK}</script></head>\n<body>\n<h1>{}</h1>\n",
        escape(&r.title),
        escape(&r.title)
    );
    if let Some(png) = &r.contact_sheet {
        let _ = write!(s, "<h2>Contact sheet</h2>\n{}\n", img(png, "contact sheet", "sheet"));
    }
    s.push_str("<h2>Evaluation</h2>\n");
    match &r.eval_table {
        Some(t) => {
            let _ = write!(s, "<pre>{}</pre>\n<p>Every figure with its parameters: eval.json.</p>\n", escape(t));
        }
        None => s.push_str("<p>No variant could be scored (see the run's log).</p>\n"),
    }
    if !r.variants.is_empty() {
        s.push_str("<h2>Variants</h2>\n<div class=\"grid\">\n");
        for (name, png) in &r.variants {
            let _ = writeln!(s, "<figure>{}<figcaption>{}</figcaption></figure>", img(png, name, "variant"), escape(name));
        }
        s.push_str("</div>\n");
    }
    if !r.loss_plots.is_empty() {
        s.push_str("<h2>Training loss</h2>\n<div class=\"grid\">\n");
        for (level, png) in &r.loss_plots {
            let name = format!("level {level}");
            let _ = writeln!(s, "<figure>{}<figcaption>{name}</figcaption></figure>", img(png, &name, "loss"));
        }
        s.push_str("</div>\n");
    }
    if !r.timings.is_empty() {
        s.push_str("<h2>Timings</h2>\n<table><tr><th>stage</th><th>seconds</th></tr>\n");
        for (what, secs) in &r.timings {
            let _ = writeln!(s, "<tr><td>{}</td><td>{secs:.1}</td></tr>", escape(what));
        }
        s.push_str("</table>\n<p>Seconds of work per stage as each stage recorded it (stages that ran concurrently overlap in wall time).</p>\n");
    }
    let _ = write!(
        s,
        "<h2>Configuration</h2>\n<p>digest {}</p>\n<pre>{}</pre>\n</body></html>\n",
        escape(&r.config_digest),
        escape(&r.config_toml)
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_inlines_every_image_and_escapes_text() {
        let png = vec![0x89, b'P', b'N', b'G'];
        let r = ReportInputs {
            title: "tower <1>".into(),
            contact_sheet: Some(png.clone()),
            eval_table: Some("a & b".into()),
            variants: vec![("variant_000".into(), png.clone())],
            loss_plots: vec![(0, png.clone()), (1, png)],
            timings: vec![("encode".into(), 1.25)],
            config_toml: "name = \"cpu\"".into(),
            config_digest: "abc".into(),
        };
        let page = html(&r);
        assert_eq!(page.matches("src=\"data:image/png;base64,iVBORw").count(), 4);
        assert!(page.contains("tower &lt;1&gt;") && page.contains("a &amp; b") && page.contains("&quot;cpu&quot;"));
        assert!(!page.contains("http://") && !page.contains("https://"), "nothing outside the page");
        assert!(page.contains("<td>encode</td><td>1.2</td>") || page.contains("<td>encode</td><td>1.3</td>"));
    }
}
