//! The self-contained HTML report: summary, per-scene tables, plots and comparison images
//! (PNGs embedded as base64 data URIs, so the page can be moved or mailed on its own).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::ablation::Ablation;
use crate::images::base64;
use crate::peers::Peer;
use crate::{read_output_file, EvalResults};
use infer::report::LEVEL_NAMES;

/// Escapes text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

fn sci(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "–".into()
    }
}

/// A relMSE in the report's scientific notation; "–" when absent or not finite.
pub(crate) fn opt_sci(v: Option<f64>) -> String {
    v.map_or_else(|| "–".into(), sci)
}

fn percent(v: Option<f64>) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "–".into(), |x| format!("{:+.1} %", 100.0 * x))
}

/// An `<img>` with the PNG `name` (in `dir`) embedded.
fn embedded_img(dir: &Path, name: &str, alt: &str, class: &str) -> Result<String> {
    let bytes = read_output_file(dir, name)?;
    Ok(format!(
        "<img class=\"{class}\" alt=\"{}\" src=\"data:image/png;base64,{}\">",
        escape(alt),
        base64(&bytes)
    ))
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.8em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}\
th{background:#eee}td.l,th.l{text-align:left}.win{color:#070;font-weight:bold}.loss{color:#a00}\
img.px{image-rendering:pixelated;width:100%;max-width:1100px}img.plot{width:100%;max-width:1120px}\
.note{background:#f6f6f0;border-left:4px solid #cc9;padding:0.5em 1em}.fail{color:#a00}";

/// Renders the page. Images are read back from `dir` (where `evaluate` wrote them).
pub fn page(results: &EvalResults, dir: &Path) -> Result<String> {
    let s = &results.summary;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>SPPM evaluation</title><style>{STYLE}</style></head><body>\n\
         <h1>Standard SPPM vs multi-level SPPM + neural reconstruction</h1>\n"
    );
    let c = &results.config;
    let _ = writeln!(
        h,
        "<p>Model <code>{}</code> ({:?} preset, {}×{} window); {} photons per pass; passes {:?}; \
         seed {}; renderer threads {}; backend {}; inference engine {}.</p>",
        escape(&c.model.display().to_string()),
        results.model.preset,
        results.model.window,
        results.model.window,
        c.photons_per_pass,
        c.passes,
        c.seed,
        if c.threads == 0 {
            "all".to_string()
        } else {
            c.threads.to_string()
        },
        escape(&c.backend),
        c.engine
            .or_else(|| model::backend::Backend::parse(&c.backend)
                .ok()
                .map(infer::Engine::default_for))
            .map_or("?".to_string(), |e| format!("{e:?}").to_lowercase())
    );
    if c.schedule == renderer::integrators::sppm::RadiusSchedule::Cppm {
        let _ = writeln!(
            h,
            "<p class=\"note\">Radius schedule: CPPM in both runs. \"Standard SPPM\" below is \
             single-level CPPM; ours is multi-level CPPM + reconstruction (docs/sppm.md).</p>"
        );
    }
    let _ = writeln!(
        h,
        "<h2>Summary at {} passes</h2>\n<p>Ours better than standard SPPM at equal time on \
         <b>{} of {}</b> evaluated scenes; median ratio ours/standard <b>{}</b>, geometric mean \
         {}; ours better than its best input level on {}; median multi-level overhead per pass \
         {} (over every scene and checkpoint). {} scene(s) failed.</p>",
        s.passes,
        s.ours_better_equal_time,
        s.scenes - s.failed,
        s.median_ratio_equal_time
            .map_or_else(|| "–".into(), |v| format!("{v:.3}")),
        s.geomean_ratio_equal_time
            .map_or_else(|| "–".into(), |v| format!("{v:.3}")),
        s.ours_better_than_best_input,
        percent(s.median_overhead),
        s.failed
    );
    if let Some(n) = &s.noise_corrected {
        let _ = writeln!(
            h,
            "<p class=\"note\">{}</p>",
            escape(&noise_corrected_sentence(n))
        );
    }
    h.push_str(
        "<table><tr><th class=\"l\">scene</th><th>ours s<br>(render+inf.)</th><th>ours relMSE</th>\
         <th>standard relMSE<br>equal time</th><th>ratio</th><th>standard relMSE<br>equal passes</th>\
         <th>best input</th><th>overhead</th></tr>\n",
    );
    for r in &results.scenes {
        let name = escape(&r.name);
        let last = r
            .eval
            .as_ref()
            .and_then(|e| e.checkpoints.iter().find(|c| c.passes == s.passes));
        match (last, &r.error) {
            (Some(c), _) => {
                let best = c.level_relmse.iter().copied().fold(f64::INFINITY, f64::min);
                let class = if c.ratio_equal_time < 1.0 {
                    "win"
                } else {
                    "loss"
                };
                let _ = writeln!(
                    h,
                    "<tr><td class=\"l\"><a href=\"#{name}\">{name}</a>{}</td><td>{:.2}</td><td>{}</td>\
                     <td>{}{}</td><td class=\"{class}\">{:.3}</td><td>{}</td><td>{} ({})</td><td>{}</td></tr>",
                    if r.reused { "†" } else { "" },
                    c.total_seconds,
                    sci(c.ours_relmse),
                    sci(c.standard_equal_time.relmse),
                    if c.standard_equal_time.extrapolated {
                        "*"
                    } else {
                        ""
                    },
                    c.ratio_equal_time,
                    opt_sci(c.standard_equal_passes),
                    sci(best),
                    escape(&c.best_level),
                    percent(c.overhead)
                );
            }
            (None, err) => {
                let _ = writeln!(
                    h,
                    "<tr><td class=\"l\">{name}</td><td class=\"l fail\" colspan=\"7\">failed: {}</td></tr>",
                    escape(err.as_deref().unwrap_or("no checkpoint at this pass count"))
                );
            }
        }
    }
    h.push_str("</table>\n");
    // Footnotes only for marks the page carries.
    let extrapolated = results.scenes.iter().any(|r| {
        r.eval.as_ref().is_some_and(|e| {
            e.checkpoints
                .iter()
                .any(|c| c.standard_equal_time.extrapolated)
        })
    });
    if extrapolated {
        h.push_str(
            "<p>* standard SPPM's curve did not reach that time; its nearest end point is \
             used.</p>\n",
        );
    }
    if results.scenes.iter().any(|r| r.reused) {
        h.push_str(
            "<p>† taken from an earlier run with the same settings (<code>--resume</code>): \
             its timings are that run's.</p>\n",
        );
    }
    peers_section(&mut h, results);
    let _ = writeln!(
        h,
        "<div class=\"note\"><p><b>Method.</b> {}</p></div>",
        escape(&results.method)
    );
    ablation_section(&mut h, &results.ablation_dual_vs_multi);

    for r in &results.scenes {
        let name = escape(&r.name);
        let _ = writeln!(h, "<h2 id=\"{name}\">{name}</h2>");
        let _ = writeln!(
            h,
            "<p><code>{}</code>, reference <code>{}</code>{}</p>",
            escape(&lexically_normal(&r.xml).display().to_string()),
            escape(&lexically_normal(&r.reference).display().to_string()),
            if r.reused {
                " (taken from an earlier run with the same settings: its timings are that run's)"
            } else {
                ""
            }
        );
        if let Some(n) = r.reference_noise.as_ref().filter(|n| n.too_noisy()) {
            let _ = writeln!(
                h,
                "<p class=\"fail\">Warning: {}.</p>",
                escape(&n.warning())
            );
        }
        let Some(e) = &r.eval else {
            let _ = writeln!(
                h,
                "<p class=\"fail\">failed: {}</p>",
                escape(r.error.as_deref().unwrap_or("unknown error"))
            );
            continue;
        };
        h.push_str("<table><tr><th>passes</th><th>render s</th><th>inference s</th><th>ours s</th><th>ours</th>");
        for l in LEVEL_NAMES {
            let _ = write!(h, "<th>input {l}</th>");
        }
        h.push_str(
            "<th>standard<br>equal time</th><th>ratio</th><th>standard<br>equal passes</th>\
             <th>standard s<br>equal passes</th><th>overhead</th></tr>\n",
        );
        for c in &e.checkpoints {
            let class = if c.ratio_equal_time < 1.0 {
                "win"
            } else {
                "loss"
            };
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td>",
                c.passes,
                c.render_seconds,
                c.inference_seconds,
                c.total_seconds,
                sci(c.ours_relmse)
            );
            for v in &c.level_relmse {
                let _ = write!(h, "<td>{}</td>", sci(*v));
            }
            let _ = writeln!(
                h,
                "<td>{}{}</td><td class=\"{class}\">{:.3}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                sci(c.standard_equal_time.relmse),
                if c.standard_equal_time.extrapolated {
                    "*"
                } else {
                    ""
                },
                c.ratio_equal_time,
                opt_sci(c.standard_equal_passes),
                c.standard_seconds_equal_passes
                    .map_or_else(|| "–".into(), |v| format!("{v:.2}")),
                percent(c.overhead)
            );
        }
        h.push_str("</table>\n");
        if let Some(p) = &r.plot {
            h.push_str(&embedded_img(
                dir,
                p,
                &format!("{} convergence", r.name),
                "plot",
            )?);
            h.push_str("<p>Left: relMSE against wall time (ours at render + inference time; input levels at render time). Right: against passes.</p>\n");
        }
        if let Some(p) = &r.comparison {
            h.push_str(&embedded_img(
                dir,
                p,
                &format!("{} comparison", r.name),
                "px",
            )?);
            let (sp, ss) = r
                .comparison_standard
                .map_or((0, f64::NAN), |p| (p.passes, p.seconds));
            let ours = e.checkpoints.last();
            let mut peers = String::new();
            for peer in [Peer::SppmOidn, Peer::PtOidn] {
                if let Some(p) = ours.and_then(|c| c.peer(peer)) {
                    let unit = match peer {
                        Peer::SppmOidn => "passes",
                        Peer::PtOidn => "spp",
                    };
                    let _ = write!(
                        peers,
                        " | {} ({} {unit}, {:.2} s incl. denoising) | its relative error",
                        peer.name(),
                        p.samples,
                        p.total_seconds
                    );
                }
            }
            let _ = writeln!(
                h,
                "<p>Left to right: standard SPPM ({sp} passes, {ss:.2} s) | ours ({} passes, {:.2} s \
                 incl. inference) | reference | relative error of standard SPPM | relative error of \
                 ours{} (per-pixel relMSE summand, log colour scale over three decades up to {}).</p>",
                ours.map_or(0, |c| c.passes),
                ours.map_or(f64::NAN, |c| c.total_seconds),
                escape(&peers),
                r.error_scale
                    .map_or_else(|| "–".into(), |v| sci(f64::from(v)))
            );
        }
        if let Some(p) = &r.inputs {
            h.push_str(&embedded_img(dir, p, &format!("{} inputs", r.name), "px")?);
            h.push_str("<p>Input levels at the last checkpoint, sharpest to smoothest: ỹ, z̃1, z̃2, z̃3, z̃4.</p>\n");
        }
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

/// Ours against the OIDN peers at equal time (absent when none was run): one row per scene
/// and checkpoint, each peer's relMSE, what it rendered, and ours / it.
fn peers_section(h: &mut String, results: &EvalResults) {
    let s = &results.summary;
    if s.peers.is_empty() {
        return;
    }
    let _ = writeln!(h, "<h2 id=\"peers\">Peers at equal time</h2>");
    for p in &s.peers {
        let _ = writeln!(
            h,
            "<p>At {} passes ours is better than <b>{}</b> on <b>{} of {}</b> scenes, median \
             ratio ours/it <b>{}</b>.</p>",
            s.passes,
            p.peer.name(),
            p.ours_better,
            p.scenes,
            p.median_ratio
                .map_or_else(|| "–".into(), |v| format!("{v:.3}"))
        );
    }
    h.push_str("<table><tr><th class=\"l\">scene</th><th>passes</th><th>ours relMSE</th>");
    for p in &s.peers {
        let _ = write!(
            h,
            "<th>{0} relMSE</th><th>{0}<br>samples, render s + OIDN s</th><th>ours / it</th>",
            p.peer.name()
        );
    }
    h.push_str("</tr>\n");
    for r in &results.scenes {
        let Some(e) = &r.eval else { continue };
        for c in &e.checkpoints {
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td>",
                escape(&r.name),
                c.passes,
                sci(c.ours_relmse)
            );
            for p in &s.peers {
                match c.peer(p.peer) {
                    Some(v) => {
                        let class = if v.ratio < 1.0 { "win" } else { "loss" };
                        let _ = write!(
                            h,
                            "<td>{}</td><td>{}, {:.2} + {:.2}</td><td class=\"{class}\">{:.3}</td>",
                            sci(v.relmse),
                            v.samples,
                            v.render_seconds,
                            v.denoise_seconds,
                            v.ratio
                        );
                    }
                    None => h.push_str("<td>–</td><td>–</td><td>–</td>"),
                }
            }
            h.push_str("</tr>\n");
        }
    }
    h.push_str(
        "</table>\n<p>Each peer renders to the first of its checkpoints at or past ours' total \
         time less the denoiser's (so it gets at least ours' time), then OIDN 2.5 (HDR, albedo + \
         normal, quality high) denoises it; the denoiser's time is the median of three calls \
         after a warm-up. SPPM + OIDN: standard SPPM with its own G-buffer; PT + OIDN: the \
         path tracer, with the G-buffer of ours' bundle.</p>\n",
    );
}

/// The dual-vs-multi table (paper Table 1), scenes as rows, models as columns.
fn ablation_section(h: &mut String, a: &Ablation) {
    let _ = writeln!(
        h,
        "<h2 id=\"dual-vs-multi\">Dual vs multi ablation (paper Table 1) at {} passes</h2>",
        a.passes
    );
    let Some(multi) = &a.multi else {
        let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&a.note));
        return;
    };
    h.push_str("<table><tr><th class=\"l\">scene</th>");
    for m in a.variants.iter().chain(std::iter::once(multi)) {
        let _ = write!(
            h,
            "<th>{}<br><code>{}</code></th>",
            escape(&m.label),
            escape(&m.dir.display().to_string())
        );
    }
    h.push_str("<th>best input level</th></tr>\n");
    for r in &a.rows {
        let _ = write!(h, "<tr><td class=\"l\">{}</td>", escape(&r.scene));
        let best = r.variants.iter().copied().fold(r.multi, f64::min);
        for v in r.variants.iter().chain(std::iter::once(&r.multi)) {
            let class = if *v == best { " class=\"win\"" } else { "" };
            let _ = write!(h, "<td{class}>{}</td>", sci(*v));
        }
        let _ = writeln!(
            h,
            "<td>{} ({})</td></tr>",
            sci(r.best_input),
            escape(&r.best_input_level)
        );
    }
    h.push_str("<tr><th class=\"l\">geometric mean / multi</th>");
    for g in &a.geomean_ratio_to_multi {
        let _ = write!(
            h,
            "<th>{}</th>",
            g.map_or_else(|| "–".into(), |v| format!("{v:.3}"))
        );
    }
    h.push_str("<th>1</th><th></th></tr>\n<tr><th class=\"l\">scenes where multi is better</th>");
    for n in &a.multi_better {
        let _ = write!(h, "<th>{n} of {}</th>", a.rows.len());
    }
    h.push_str("<th></th><th></th></tr>\n</table>\n");
    let _ = writeln!(
        h,
        "<p>relMSE; the lowest per scene in bold green. {}</p>",
        escape(&a.note)
    );
}

/// `path` with `.` and `dir/..` pairs removed by name (`a/../b/./c` → `b/c`); leading `..`
/// stay. For display: the file system is not consulted.
fn lexically_normal(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            Component::CurDir => {}
            Component::ParentDir
                if matches!(out.components().next_back(), Some(Component::Normal(_))) =>
            {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// The summary's ratios with the references' noise taken out, as one sentence.
pub fn noise_corrected_sentence(n: &crate::NoiseCorrected) -> String {
    let value = |v: Option<f64>| v.map_or_else(|| "–".into(), |x| format!("{x:.3}"));
    let mut out = format!(
        "With the references' own noise taken out of both errors (where it is at most {} of \
         each; ratios measured against noisy references are pulled toward 1): median ours / \
         standard SPPM {} over {} scene(s)",
        crate::ReferenceNoise::CORRECTABLE,
        value(n.median_ratio_equal_time),
        n.scenes
    );
    for p in &n.peers {
        out += &format!(
            ", ours / {} {} over {}",
            p.peer.name(),
            value(p.median_ratio),
            p.scenes
        );
    }
    out + "."
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup() {
        assert_eq!(
            escape("a<b>&\"c'"),
            "a&lt;b&gt;&amp;&quot;c&#39;".to_string()
        );
        assert_eq!(percent(Some(0.123)), "+12.3 %");
        assert_eq!(percent(None), "–");
        assert_eq!(sci(f64::NAN), "–");
        assert_eq!(
            lexically_normal(Path::new("/tmp/a/mix/../my/./scene.xml")),
            Path::new("/tmp/a/my/scene.xml")
        );
        assert_eq!(
            lexically_normal(Path::new("../shared/x/../cbox.xml")),
            Path::new("../shared/cbox.xml")
        );
    }

    #[test]
    fn ablation_table_lists_every_model_and_scene() {
        use crate::ablation::{not_run, AblationModel, AblationRow};
        use model::{ModelConfig, Preset};
        let mut h = String::new();
        ablation_section(&mut h, &not_run(16));
        assert!(h.contains("Not run"));
        let m = |levels: Vec<usize>, dir: &str| {
            AblationModel::new(
                dir.into(),
                &ModelConfig::preset(Preset::Small).with_levels(levels),
            )
        };
        let a = Ablation {
            note: "n".into(),
            passes: 16,
            multi: Some(m(vec![0, 1, 2, 3, 4], "runs/multi")),
            variants: vec![m(vec![0, 2], "runs/dual")],
            rows: vec![AblationRow {
                scene: "s<1>".into(),
                multi: 0.25,
                variants: vec![0.5],
                best: "x".into(),
                best_input: 0.125,
                best_input_level: "z3".into(),
            }],
            geomean_ratio_to_multi: vec![Some(2.0)],
            multi_better: vec![1],
        };
        let mut h = String::new();
        ablation_section(&mut h, &a);
        for want in [
            "Dual (y, z2)",
            "Multi (y, z1, ..., z4)",
            "runs/dual",
            "s&lt;1&gt;",
            "<td>5.000e-1</td>",
            "<td class=\"win\">2.500e-1</td>",
            "<th>2.000</th>",
            "<td>1.250e-1 (z3)</td>",
            "1 of 1",
        ] {
            assert!(h.contains(want), "missing {want} in {h}");
        }
    }
}
