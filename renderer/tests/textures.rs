//! Texture tiles on lavapipe with the validation layer on: the Puget photo and a baked relief
//! streamed into texture slots within the frame's byte budget, no colour seam where tiles meet
//! on screen, and tiles whose fine mips have not arrived sampling their finest resident mip.
//! Each measure has a negative control that must fail it (a fault injected into the renderer).

use std::path::Path;

mod common;

use common::{flight, flight_with_fault, is_sky, puget, puget_textured, s, vkterrain};

fn summary(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("frames.json")).expect("summary");
    serde_json::from_str(&text).expect("summary is JSON")
}

/// Column `name` of the run's frame log.
fn column(out: &Path, name: &str) -> Vec<f64> {
    common::log_column(&out.join("frames.csv"), name)
}

/// With the slots in either format: BC1 as stored, or decoded to R5G6B5 (lavapipe's default).
#[test]
fn photo_and_relief_stream_into_their_slots_within_the_budget() {
    for (photo, format) in [(true, "bc1"), (false, "bc1"), (true, "rgb565")] {
        let dir = tempfile::tempdir().expect("tempdir");
        let set = puget_textured(dir.path(), photo);
        let out = dir.path().join("run");
        std::fs::create_dir_all(&out).expect("out");
        let budget = 0.5;
        let frames = flight(
            &set,
            &out,
            "flyover",
            16,
            &[
                "--upload-budget-mb",
                &budget.to_string(),
                "--texture-format",
                format,
            ],
        );
        let sum = summary(&out);
        assert_eq!(sum["validation_messages"], 0);
        let texture_mb = sum["texture_mb"].as_f64().expect("texture_mb");
        let sent_mb = sum["upload_mb_textures"]
            .as_f64()
            .expect("upload_mb_textures");
        assert!(texture_mb > 0.0, "no texture slots: {sum}");
        // Puget's 16 tiles all get a slot, so nothing is evicted and no mip is sent twice.
        assert!(
            sent_mb > 0.0 && sent_mb <= texture_mb,
            "{sent_mb} MB of textures sent into {texture_mb} MB of slots"
        );
        // Geometry goes first; textures take what it leaves of the budget, plus new tiles'
        // base mips (at most 32 texels across: a few hundred bytes each as BC1, four times
        // that decoded).
        let geometry = column(&out, "upload_bytes");
        let textures = column(&out, "upload_bytes_textures");
        let drawn = column(&out, "tiles_drawn");
        let budget_bytes = budget * f64::from(1 << 20);
        for ((g, t), n) in geometry.iter().zip(&textures).zip(&drawn) {
            assert!(
                g + t <= budget_bytes.max(*g) + n * if format == "bc1" { 1024.0 } else { 4096.0 },
                "frame sent {g} bytes of geometry and {t} of textures with a {budget_bytes} budget"
            );
        }
        let free = column(&out, "texture_slots_free");
        assert!(
            free.windows(2).all(|w| w[1] <= w[0]),
            "slots freed: {free:?}"
        );
        assert!(free[0] < 16.0, "no slot taken on the first frame: {free:?}");
        // The textured frames are not the height-tinted ones.
        let tint_out = dir.path().join("tint");
        std::fs::create_dir_all(&tint_out).expect("out");
        let tint = flight(&set, &tint_out, "flyover", 16, &["--shading", "tint"]);
        let last = frames.len() - 1;
        let differ = frames[last]
            .pixels()
            .zip(tint[last].pixels())
            .filter(|(a, b)| !is_sky(a) && a.0[..3] != b.0[..3])
            .count();
        let terrain = frames[last].pixels().filter(|p| !is_sky(p)).count();
        assert!(
            differ * 2 > terrain,
            "only {differ} of {terrain} terrain pixels differ from the tint"
        );
    }
}

/// The colour step (largest channel difference) between neighbouring pixels on either side of
/// a tile border, summed over every such pair the `tiles` shading shows, and the steps of the
/// same pairs moved 5 pixels off the border to either side (averaged; both must lie inside
/// one tile and off the sky): a seam makes the first larger than the second, while the photo's
/// own detail, which varies over the image, is matched pair by pair. Returns both sums and the
/// number of pairs.
fn border_steps(tiles: &[image::RgbaImage], photo: &[image::RgbaImage]) -> (f64, f64, usize) {
    const OFF: i64 = 5;
    let (mut across, mut nearby, mut pairs) = (0.0, 0.0, 0usize);
    for (ids, img) in tiles.iter().zip(photo) {
        let (w, h) = (i64::from(ids.width()), i64::from(ids.height()));
        let inside = |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h;
        let id = |x: i64, y: i64| ids.get_pixel(x as u32, y as u32);
        let colour = |x: i64, y: i64| img.get_pixel(x as u32, y as u32);
        let step = |(ax, ay): (i64, i64), (bx, by): (i64, i64)| {
            let (a, b) = (colour(ax, ay).0, colour(bx, by).0);
            (0..3)
                .map(|c| (i32::from(a[c]) - i32::from(b[c])).abs())
                .max()
                .unwrap_or(0) as f64
        };
        // A pair within one tile, terrain in both images.
        let plain = |a: (i64, i64), b: (i64, i64)| {
            inside(a.0, a.1)
                && inside(b.0, b.1)
                && id(a.0, a.1) == id(b.0, b.1)
                && !is_sky(id(a.0, a.1))
                && !is_sky(colour(a.0, a.1))
                && !is_sky(colour(b.0, b.1))
        };
        for y in 0..h {
            for x in 0..w {
                for (dx, dy) in [(1, 0), (0, 1)] {
                    let (a, b) = ((x, y), (x + dx, y + dy));
                    if !inside(b.0, b.1)
                        || id(a.0, a.1) == id(b.0, b.1)
                        || is_sky(id(a.0, a.1))
                        || is_sky(id(b.0, b.1))
                        || is_sky(colour(a.0, a.1))
                        || is_sky(colour(b.0, b.1))
                    {
                        continue;
                    }
                    let before = (
                        (x - OFF * dx, y - OFF * dy),
                        (b.0 - OFF * dx, b.1 - OFF * dy),
                    );
                    let after = (
                        (x + OFF * dx, y + OFF * dy),
                        (b.0 + OFF * dx, b.1 + OFF * dy),
                    );
                    if !plain(before.0, before.1) || !plain(after.0, after.1) {
                        continue;
                    }
                    across += step(a, b);
                    nearby += 0.5 * (step(before.0, before.1) + step(after.0, after.1));
                    pairs += 1;
                }
            }
        }
    }
    (across, nearby, pairs)
}

#[test]
fn tile_borders_show_no_colour_seam() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = puget_textured(dir.path(), true);
    let run = |name: &str, extra: &[&str], fault: Option<&str>| {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("out");
        // Warm: every tile's textures resident, so neighbours differ only as the photo does.
        let mut args = vec!["--size", "512x384", "--warmup"];
        args.extend(extra);
        flight_with_fault(&set, &out, "flyover", 12, &args, fault)
    };
    let borders = run("tiles", &["--shading", "tiles"], None);
    // Lines through the middle of the tiles: also BC1 block edges (whose colour steps are
    // part of the compressed source), but not tile borders.
    let middles = run(
        "middles",
        &["--shading", "tiles", "--tile-grid-offset", "128"],
        None,
    );
    let photo = run("photo", &[], None);
    let shifted = run("seam", &[], Some("texture-seam"));
    let ratio = |lines: &[image::RgbaImage], img: &[image::RgbaImage]| {
        let (across, beside, pairs) = border_steps(lines, img);
        assert!(pairs > 1000, "only {pairs} pixel pairs across the lines");
        across / beside
    };
    let (at_borders, at_middles) = (ratio(&borders, &photo), ratio(&middles, &photo));
    let (bad_borders, bad_middles) = (ratio(&borders, &shifted), ratio(&middles, &shifted));
    eprintln!(
        "colour steps across / 5 px beside: tile borders {at_borders:.3}, tile middles \
         {at_middles:.3}; with every other tile's texture moved 4 samples: {bad_borders:.3} and \
         {bad_middles:.3}"
    );
    // Across a tile border the rendered photo changes as across any other block edge.
    assert!(
        at_borders <= 1.1 * at_middles,
        "seams: steps across tile borders {at_borders:.3} x those beside, {at_middles:.3} x mid-tile"
    );
    // Control: a misregistration of a few texels at every other tile shows.
    assert!(
        bad_borders > 1.2 * bad_middles,
        "the seam measure missed misregistered tiles ({bad_borders:.3} against {bad_middles:.3})"
    );
}

/// Terrain pixels that are pure black (no Puget texel is).
fn black(frames: &[image::RgbaImage]) -> usize {
    frames
        .iter()
        .flat_map(|f| f.pixels())
        .filter(|p| p.0[..3] == [0, 0, 0])
        .count()
}

#[test]
fn tiles_without_their_fine_mips_sample_the_finest_resident_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = puget_textured(dir.path(), false);
    // So little budget that fine mips arrive over many frames.
    let extra = ["--upload-budget-mb", "0.05", "--size", "320x240"];
    let out = dir.path().join("clamped");
    std::fs::create_dir_all(&out).expect("out");
    let clamped = flight(&set, &out, "flyover", 8, &extra);
    let coarser: f64 = column(&out, "tiles_texture_coarser").iter().sum();
    assert!(
        coarser > 0.0,
        "every texture arrived at once; the clamp was not exercised"
    );
    let bad_out = dir.path().join("unclamped");
    std::fs::create_dir_all(&bad_out).expect("out");
    let unclamped = flight_with_fault(
        &set,
        &bad_out,
        "flyover",
        8,
        &extra,
        Some("texture-no-clamp"),
    );
    let (good, bad) = (black(&clamped), black(&unclamped));
    eprintln!("black terrain pixels: {good} clamped, {bad} without the clamp");
    assert_eq!(good, 0, "{good} pixels sampled a mip nothing was copied to");
    assert!(
        bad > 100,
        "the control did not sample missing mips ({bad} black pixels)"
    );
}

#[test]
fn photo_shading_of_a_set_without_textures_is_one_clear_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = puget(dir.path());
    let o = vkterrain(&[s(&set), "--headless", "--frames", "1", "--shading", "photo"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("no texture tiles") && err.contains(s(&set)),
        "{err}"
    );
}

/// Texture slots decoded to R5G6B5 on the CPU (`--texture-format rgb565`, the default on a
/// software rasteriser: `settings::texture_format_for`) draw what BC1 slots draw: the Puget
/// photo's flyover, every frame within 4 of 255 per channel of the BC1 frame (R5G6B5 steps are
/// 8 and 4 of 255; both decode the same blocks), in four times the slot memory. Where the
/// device decides, a software rasteriser decodes. The control: a texture moved by 4 samples on
/// every other tile (`texture-seam`) is far outside that tolerance.
#[test]
fn slots_decoded_to_rgb565_draw_what_bc1_slots_draw() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = puget_textured(dir.path(), true);
    let run = |name: &str, extra: &[&str], fault: Option<&str>| {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("out");
        let frames = flight_with_fault(&set, &out, "flyover", 12, extra, fault);
        (frames, summary(&out))
    };
    let (bc1, bc1_sum) = run("bc1", &["--texture-format", "bc1"], None);
    let (rgb, rgb_sum) = run("rgb565", &["--texture-format", "rgb565"], None);
    // The largest and the mean difference of a channel over a frame.
    let differ = |a: &image::RgbaImage, b: &image::RgbaImage| {
        let d: Vec<u8> = a
            .pixels()
            .zip(b.pixels())
            .flat_map(|(p, q)| (0..3).map(move |c| p[c].abs_diff(q[c])))
            .collect();
        let mean = d.iter().map(|&x| f64::from(x)).sum::<f64>() / d.len() as f64;
        (d.iter().copied().max().unwrap_or(0), mean)
    };
    for (k, (a, b)) in bc1.iter().zip(&rgb).enumerate() {
        let (max, mean) = differ(a, b);
        assert!(
            max <= 4 && mean < 1.0,
            "frame {k}: {max} at most, {mean} on average"
        );
    }
    let mb = |s: &serde_json::Value| s["texture_mb"].as_f64().expect("texture_mb");
    let ratio = mb(&rgb_sum) / mb(&bc1_sum);
    assert!((3.5..=4.5).contains(&ratio), "slots {ratio}x BC1's");
    let (_, auto) = run("auto", &[], None);
    let software = auto["device"]
        .as_str()
        .is_some_and(|d| d.contains("llvmpipe"));
    let chosen = if software { mb(&rgb_sum) } else { mb(&bc1_sum) };
    assert_eq!(mb(&auto), chosen, "{auto}");

    // The control.
    let (seam, _) = run(
        "seam",
        &["--texture-format", "rgb565"],
        Some("texture-seam"),
    );
    let worst = bc1
        .iter()
        .zip(&seam)
        .map(|(a, b)| differ(a, b).0)
        .max()
        .unwrap_or(0);
    assert!(
        worst > 32,
        "a texture moved by 4 samples differs by {worst} at most"
    );
}

/// The tiles shaded by their texture take a pipeline whose fragment shader has the texture's
/// path alone (fewer inputs to interpolate): the Puget photo's flyover draws the same pixels,
/// frame for frame, as with the one fragment shader for every shading
/// (`--one-fragment-shader`), with most tiles drawn by the photo pipeline and none without it;
/// so does a flight with slots for a few tiles alone, whose other tiles are tinted by the
/// default pipeline beside the photo one's. "The same" within the sampler's own rounding: a
/// tile whose every mip is resident samples with implicit derivatives (`WHOLE_MIPS`), the one
/// shader with the same derivatives given, and lavapipe rounds the two levels differently on
/// 0.6-2.2% of a frame's pixels, by at most 9 levels of 255 ([`same_samples`]). The control:
/// the photo pipeline's tiles sampled 4 samples off every other tile (`texture-seam`) draw
/// frames beyond that.
#[test]
fn the_photo_pipeline_draws_what_the_one_fragment_shader_draws() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = puget_textured(dir.path(), true);
    let run = |name: &str, extra: &[&str], fault: Option<&str>| {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("out");
        let frames = flight_with_fault(&set, &out, "flyover", 12, extra, fault);
        let photo: f64 = column(&out, "tiles_photo").iter().sum();
        let drawn: f64 = column(&out, "tiles_drawn").iter().sum();
        (frames, photo, drawn)
    };
    // Then with slots for a few tiles alone (1/500 of the budget): the others are tinted.
    for (share, few) in [("0.25", false), ("0.002", true)] {
        let extra = ["--texture-share", share];
        let (photo, by_photo, drawn) = run("photo", &extra, None);
        let one_shader = [&extra[..], &["--one-fragment-shader"]].concat();
        let (one, by_one, _) = run("one", &one_shader, None);
        for (k, (a, b)) in photo.iter().zip(&one).enumerate() {
            let (share_of, max) = sampled_apart(a, b);
            assert!(
                same_samples(a, b),
                "share {share}: frame {k} differs with the photo pipeline on {:.2}% of its \
                 pixels, by up to {max}",
                100.0 * share_of
            );
        }
        eprintln!("share {share}: {by_photo} of {drawn} tile draws by the photo pipeline");
        assert_eq!(by_one, 0.0);
        if few {
            assert!(
                by_photo > 0.0 && by_photo < drawn,
                "share {share}: {by_photo} of {drawn}"
            );
        } else {
            assert!(
                by_photo * 2.0 > drawn,
                "share {share}: {by_photo} of {drawn}"
            );
        }
    }
    let (one, ..) = run("one", &["--one-fragment-shader"], None);
    // The control.
    let (seam, ..) = run("seam", &[], Some("texture-seam"));
    let differing = seam
        .iter()
        .zip(&one)
        .filter(|(a, b)| !same_samples(a, b))
        .count();
    assert!(
        differing >= 6,
        "a texture seam changed {differing} of 12 frames"
    );
}

/// The share of pixels whose colour differs between `a` and `b`, and the largest difference
/// of a channel.
fn sampled_apart(a: &image::RgbaImage, b: &image::RgbaImage) -> (f64, u8) {
    let mut differing = 0usize;
    let mut max = 0u8;
    for (p, q) in a.pixels().zip(b.pixels()) {
        let d = (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap_or(0);
        differing += usize::from(d > 0);
        max = max.max(d);
    }
    (differing as f64 / f64::from(a.width() * a.height()), max)
}

/// `a` and `b` are the same frame but for the sampler's own rounding of its level: at most 5%
/// of the pixels differ, by at most 16 levels a channel (measured: at most 2.2%, by 9; the
/// control, a seam, 13-52% by 100-219).
fn same_samples(a: &image::RgbaImage, b: &image::RgbaImage) -> bool {
    let (share, max) = sampled_apart(a, b);
    a.dimensions() == b.dimensions() && share <= 0.05 && max <= 16
}
