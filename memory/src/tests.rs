//! The policy's rules, one test each, and its safety properties on random traces.

use proptest::prelude::*;

use crate::cost::tests::tile;
use crate::*;

fn req(tile: TileId, wanted: u32) -> Request {
    Request { tile, wanted }
}

/// The requested tiles with nothing resident (their presence may go over the budget).
fn new_tiles(m: &Manager, requests: &[Request]) -> Vec<TileId> {
    requests
        .iter()
        .map(|r| r.tile)
        .filter(|&t| m.resident_levels(t).is_none())
        .collect()
}

/// Checks that `p` sent more than `budget` only as [`Manager::plan_frame`] allows: for the
/// presence of the tiles in `new` (each one's level 0, sent whatever the budget; refinement
/// then has only what presence left), or for one step of one tile (one level's block and index
/// array) taken alone, when the frame sent nothing else. Also that the counters say what was
/// sent and by how much it went over.
fn check_budget(p: &FramePlan, new: &[TileId], budget: u64) -> Result<(), String> {
    let level = |part: Part| match part {
        Part::Positions(l) | Part::Morph(l) | Part::Indices(l) => l,
    };
    let sent: Vec<&Upload> = p.uploads.iter().filter(|u| u.sent() > 0).collect();
    let total: u64 = sent.iter().map(|u| u.sent()).sum();
    let counted = p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
    let over = p.stats.upload_overshoot_bytes;
    if (counted, over) != (total, total.saturating_sub(budget)) {
        return Err(format!(
            "the uploads send {total} bytes over a budget of {budget}; the counters say \
             {counted}, {over} over"
        ));
    }
    // Each new tile's level 0 parts, once each.
    let mut presence_parts: Vec<(TileId, Part)> = Vec::new();
    let mut presence = 0;
    for u in &sent {
        let part = (u.tile, u.part);
        if level(u.part) == 0 && new.contains(&u.tile) && !presence_parts.contains(&part) {
            presence_parts.push(part);
            presence += u.sent();
        }
    }
    let step = |u: &Upload| (u.tile, level(u.part));
    let alone = presence == 0 && sent.windows(2).all(|w| step(w[0]) == step(w[1]));
    if total <= budget.max(presence) || alone {
        Ok(())
    } else {
        Err(format!(
            "{total} bytes sent over a budget of {budget}, {presence} of them presence, and \
             not one step alone: {sent:?}"
        ))
    }
}

fn config(pool: u64, upload: u64) -> Config {
    Config {
        pool_bytes: pool,
        upload_budget: upload,
        ..Config::default()
    }
}

/// A block whose positions travel as a compact stream (decoded on the GPU) costs its stream on
/// the bus and its positions in the pool: the upload says both, the budget counts the stream,
/// so a budget that refines one level with positions refines further with streams, into the
/// same chunk.
#[test]
fn streamed_blocks_cost_their_stream_on_the_bus_and_their_positions_in_the_pool() {
    // Without morph rows, as the default shaders draw.
    let mut plain = tile(6, 50);
    for l in &mut plain.levels {
        l.morph = 0;
    }
    let mut streamed = plain.clone();
    for l in &mut streamed.levels {
        l.stream = Some(l.positions / 3);
    }
    let built = |pool, upload| Config {
        index_arrays: IndexArrays::Built,
        ..config(pool, upload)
    };
    // Presence at level 0, then a budget that covers block 1 sent as positions.
    let budget = plain.block_sent(1);
    let mut levels = Vec::new();
    for t in [&plain, &streamed] {
        let mut m = Manager::new(vec![t.clone()], built(64 << 20, budget));
        let p = m.plan_frame(0, None, &[req(0, 0)], true);
        assert_eq!(p.grants[0].level, Some(0));
        let p = m.plan_frame(1, Some(0), &[req(0, 5)], true);
        check_budget(&p, &[], budget).expect("within the budget");
        for u in p
            .uploads
            .iter()
            .filter(|u| matches!(u.part, Part::Positions(_)))
        {
            let Part::Positions(j) = u.part else { continue };
            let l = &t.levels[j as usize];
            let sent = l.stream.unwrap_or(l.positions);
            assert_eq!((u.bytes, u.stream, u.sent()), (l.positions, l.stream, sent));
            assert_eq!(u.dst - u.chunk, t.positions_before(j), "the pool's layout");
        }
        levels.push(p.grants[0].level.expect("drawn"));
    }
    // The control: with positions the budget takes one level; with streams a third the size,
    // two (blocks double each level: 1/3 + 2/3 of block 1's bytes).
    assert_eq!(levels, vec![1, 2]);
}

#[test]
fn progressive_refinement_sends_only_new_blocks_and_one_index_array() {
    let t = tile(6, 50);
    let mut m = Manager::new(vec![t.clone()], config(64 << 20, 1 << 30));
    let p = m.plan_frame(0, None, &[req(0, 2)], true);
    assert_eq!(p.grants[0].level, Some(2));
    // Presence (level 0) then the step to 2: blocks 0..=2, index arrays 0 and 2.
    let blocks: u64 = (0..=2).map(|j| t.block_bytes(j)).sum();
    assert_eq!(p.stats.upload_bytes_blocks, blocks);
    assert_eq!(
        p.stats.upload_bytes_indices,
        t.levels[0].indices + t.levels[2].indices
    );
    let p = m.plan_frame(1, Some(0), &[req(0, 4)], true);
    assert_eq!(p.grants[0].level, Some(4));
    assert_eq!(
        p.stats.upload_bytes_blocks,
        t.block_bytes(3) + t.block_bytes(4)
    );
    assert_eq!(p.stats.upload_bytes_indices, t.levels[4].indices);
    assert_eq!(
        p.stats.upload_bytes_coarser, 0,
        "refining is not coarsening"
    );
    // Back to a coarser level: its index array only.
    let p = m.plan_frame(2, Some(1), &[req(0, 1)], true);
    assert_eq!(
        (p.grants[0].level, p.stats.upload_bytes_blocks),
        (Some(1), 0)
    );
    assert_eq!(p.stats.upload_bytes_indices, t.levels[1].indices);
    assert_eq!(p.stats.upload_bytes_coarser, t.levels[1].indices);
    m.check().unwrap();
}

/// A tile granted its level 0 and its wanted level in one frame gets both arrays planned into
/// the same place; only the later is built (and counted), since two builds must not write the
/// same indices. Builds elsewhere are all kept.
#[test]
fn a_build_overwritten_in_the_same_frame_is_left_out() {
    let t = tile(6, 50);
    let mut c = config(64 << 20, 1 << 30);
    c.index_arrays = IndexArrays::Built;
    let mut m = Manager::new(vec![t.clone(), t.clone()], c);
    let p = m.plan_frame(0, None, &[req(0, 4), req(1, 0)], true);
    let planned: Vec<&Upload> = p.uploads.iter().filter(|u| u.built).collect();
    let kept = gpu_builds(&p.uploads);
    let parts = |us: &[&Upload]| us.iter().map(|u| (u.tile, u.part)).collect::<Vec<_>>();
    let all = parts(&planned);
    assert_eq!(all.len(), 3, "{all:?}");
    for p in [
        (0, Part::Indices(0)),
        (0, Part::Indices(4)),
        (1, Part::Indices(0)),
    ] {
        assert!(all.contains(&p), "{p:?} not in {all:?}");
    }
    // In plan order, tile 0's level 0 left out.
    let order = |p| all.iter().position(|&q| q == p);
    assert!(order((0, Part::Indices(4))) > order((0, Part::Indices(0))));
    let mut want = vec![(0, Part::Indices(4)), (1, Part::Indices(0))];
    want.sort_by_key(|&p| order(p));
    assert_eq!(parts(&kept), want);
    assert_eq!(p.stats.index_builds, 2);
    let bytes = t.levels[4].indices + t.levels[0].indices;
    assert_eq!(p.stats.index_build_bytes, bytes);
    // The next frame refines tile 0 again: one build, nothing left out.
    let p = m.plan_frame(1, Some(0), &[req(0, 5), req(1, 0)], true);
    assert_eq!(parts(&gpu_builds(&p.uploads)), [(0, Part::Indices(5))]);
}

/// Index arrays built on the GPU take their pool space but none of the upload budget: a
/// budget that holds the blocks of a step but not its index array refines at once when the
/// arrays are built, and waits a frame per step when they are sent (the control).
#[test]
fn built_index_arrays_cost_pool_space_but_no_upload_budget() {
    let t = tile(6, 50);
    let budget = (3..=5).map(|j| t.block_bytes(j)).sum::<u64>();
    let run = |arrays: IndexArrays| {
        let mut c = config(64 << 20, budget);
        c.index_arrays = arrays;
        let mut m = Manager::new(vec![t.clone()], c);
        m.plan_frame(0, None, &[req(0, 2)], true);
        let mut levels = Vec::new();
        for f in 1..4 {
            let new = new_tiles(&m, &[req(0, 5)]);
            let p = m.plan_frame(f, Some(f - 1), &[req(0, 5)], true);
            let indices: Vec<&Upload> = p
                .uploads
                .iter()
                .filter(|u| matches!(u.part, Part::Indices(_)))
                .collect();
            for u in &indices {
                assert_eq!(u.built, arrays == IndexArrays::Built);
            }
            let built: u64 = indices.iter().filter(|u| u.built).map(|u| u.bytes).sum();
            assert_eq!(
                (p.stats.index_builds, p.stats.index_build_bytes),
                (indices.iter().filter(|u| u.built).count() as u64, built)
            );
            check_budget(&p, &new, budget).unwrap();
            if arrays == IndexArrays::Built {
                assert_eq!(p.stats.upload_bytes_indices, 0, "built arrays are not sent");
            }
            levels.push(p.grants[0].level.unwrap());
            m.check().unwrap();
        }
        // The pool holds the drawn array either way.
        let (_, index) = m.resident_levels(0).unwrap();
        (levels, index)
    };
    let (built, index) = run(IndexArrays::Built);
    assert_eq!(built, vec![5, 5, 5], "built: one frame to level 5");
    assert_eq!(index, Some(5));
    let (sent, _) = run(IndexArrays::Sent);
    assert!(sent[0] < 5, "sent: the index array must not fit ({sent:?})");
}

#[test]
fn a_tile_takes_the_tightest_class_for_its_wanted_level_and_moves_when_it_outgrows_it() {
    let t = tile(9, 200);
    let mut m = Manager::new(vec![t.clone()], config(64 << 20, 1 << 30));
    m.plan_frame(0, None, &[req(0, 1)], true);
    let (_, size) = m.chunk_of(0).unwrap();
    assert_eq!(
        size,
        m.classes().sizes[m.classes().class_for(t.need(1)).unwrap()]
    );
    assert!(size < t.need(8));
    let p = m.plan_frame(1, Some(0), &[req(0, 8)], true);
    assert_eq!(p.grants[0].level, Some(8));
    assert_eq!(p.stats.chunk_moves, 1);
    // The held blocks moved inside the pool (positions and morph rows of blocks 0..=1).
    let held = t.positions_before(2) + t.morph_before(2);
    assert_eq!(p.stats.chunk_move_bytes, held);
    // ... and were not sent again.
    let new: u64 = (2..=8).map(|j| t.block_bytes(j)).sum();
    assert_eq!(p.stats.upload_bytes_blocks, new);
    assert!(m.chunk_of(0).unwrap().1 >= t.need(8));
    m.check().unwrap();
}

#[test]
fn every_visible_tile_gets_level_0_before_any_tile_is_refined() {
    let tiles: Vec<TileCost> = (0..8).map(|_| tile(6, 100)).collect();
    // Budget for roughly one refinement step a frame.
    let budget = tiles[0].block_bytes(3) + tiles[0].levels[3].indices;
    let mut m = Manager::new(tiles.clone(), config(64 << 20, budget));
    let requests: Vec<Request> = (0..8).map(|t| req(t, 5)).collect();
    let new = new_tiles(&m, &requests);
    let p = m.plan_frame(0, None, &requests, true);
    check_budget(&p, &new, budget).unwrap();
    assert!(p.grants.iter().all(|g| g.level.is_some()));
    assert_eq!(p.stats.tiles_missing, 0);
    assert!(p.stats.tiles_coarser >= 7);
    assert!(p.stats.uploads_deferred_bytes > 0);
    // Refinement goes front to back: the nearest tile is the finest.
    let levels: Vec<u32> = p.grants.iter().map(|g| g.level.unwrap()).collect();
    assert!(levels.windows(2).all(|w| w[0] >= w[1]), "{levels:?}");
    // Flying on, every tile arrives, each frame within the budget but for a step alone.
    let mut frame = 1;
    loop {
        let new = new_tiles(&m, &requests);
        let p = m.plan_frame(frame, Some(frame - 1), &requests, true);
        check_budget(&p, &new, budget).unwrap();
        if p.stats.tiles_coarser == 0 {
            assert_eq!(p.stats.uploads_deferred_bytes, 0);
            break;
        }
        frame += 1;
        assert!(frame < 100, "never converged");
    }
    m.check().unwrap();
}

#[test]
fn a_step_larger_than_the_budget_is_taken_alone() {
    let t = tile(5, 400);
    let mut m = Manager::new(vec![t.clone()], config(64 << 20, 16));
    let p = m.plan_frame(0, None, &[req(0, 4)], true);
    assert_eq!(
        p.grants[0].level,
        Some(0),
        "presence only in the first frame"
    );
    for f in 1..=4 {
        let p = m.plan_frame(f, Some(f - 1), &[req(0, 4)], true);
        assert_eq!(p.grants[0].level, Some(f as u32), "one level a frame");
    }
}

#[test]
fn tiles_drawn_by_frames_in_flight_are_not_evicted() {
    let t = tile(3, 100);
    // A pool of exactly one chunk: the second tile needs the first one's.
    let mut c = config(0, 1 << 30);
    c.pool_bytes = Manager::new(vec![t.clone()], c).classes().sizes[0];
    let mut m = Manager::new(vec![t.clone(), t.clone()], c);
    assert_eq!(m.pool_bytes(), m.classes().sizes[0]);
    m.plan_frame(0, None, &[req(0, 0)], true);
    // Frame 0 still in flight: tile 1 must wait.
    let p = m.plan_frame(1, None, &[req(1, 0)], true);
    assert_eq!((p.grants[0].level, p.stats.evictions), (None, 0));
    assert_eq!(p.stats.tiles_missing, 1);
    // Frame 1 requested tile 0? No, but frame 0 drew it: still protected while 0 runs.
    let p = m.plan_frame(2, Some(0), &[req(1, 0)], true);
    assert_eq!((p.grants[0].level, p.stats.evictions), (Some(0), 1));
    assert!(m.resident_levels(0).is_none());
    m.check().unwrap();
}

#[test]
fn the_mixture_weighs_age_against_waste() {
    // Two old chunks: a tight one used recently, a loose one used long ago.
    let small = tile(2, 50);
    let big = tile(9, 300);
    let run = |weight: f64| {
        let mut c = config(0, 1 << 30);
        c.weight = weight;
        let tiles = vec![big.clone(), small.clone(), small.clone()];
        // Exactly one chunk of each class the test uses.
        let mut classes = ClassPlan::new(&Manager::needs(&tiles, c.scheme), 1 << 40, 2.0);
        classes.counts.iter_mut().for_each(|n| *n = 0);
        let (a, b) = (
            classes.class_for(small.need(1)).unwrap(),
            classes.class_for(big.need(8)).unwrap(),
        );
        (classes.counts[a], classes.counts[b]) = (1, 1);
        let mut m = Manager::with_classes(tiles, c, classes);
        m.plan_frame(0, None, &[req(0, 8)], true); // the big chunk, used at frame 0
        m.plan_frame(1, Some(0), &[req(1, 1)], true); // the small chunk
        for f in 2..50 {
            m.plan_frame(f, Some(f - 1), &[req(1, 1)], true); // small one stays young
        }
        // Tile 2 needs a small chunk: evict the young tight one or the old big one?
        m.plan_frame(50, Some(49), &[req(2, 1)], true);
        (
            m.resident_levels(0).is_some(),
            m.resident_levels(1).is_some(),
        )
    };
    // Pure LRU: the old big chunk goes, although it wastes most of it.
    assert_eq!(run(0.0), (false, true));
    // Heavily weighted toward tight fits: the young small chunk goes.
    assert_eq!(run(10.0), (true, false));
}

#[test]
fn belady_evicts_the_tile_used_farthest_in_the_future() {
    let t = tile(2, 100);
    let mut c = config(0, 1 << 30);
    c.victim = Victim::Belady;
    c.pool_bytes = 2 * Manager::new(vec![t.clone()], c).classes().sizes[0];
    let mut m = Manager::new(vec![t.clone(), t.clone(), t.clone()], c);
    // Trace: 0, 1, then 2 (evicts), then 0 again soon, 1 never.
    let mut trace = trace::Trace::default();
    for tiles in [vec![0], vec![1], vec![2], vec![0]] {
        trace
            .frames
            .push(tiles.into_iter().map(|t| req(t, 0)).collect());
    }
    m.set_oracle(Box::new(trace.next_use()));
    for (f, frame) in trace.frames.iter().enumerate() {
        let f = f as u64;
        m.plan_frame(f, f.checked_sub(1), frame, true);
        if f == 2 {
            assert!(m.resident_levels(0).is_some(), "tile 0 is needed next");
            assert!(m.resident_levels(1).is_none());
        }
    }
}

/// A whole tile is drawable at every level: the grant of each level points at the index array
/// the upload wrote for it (4-aligned), and every block's positions follow block 0's.
#[test]
fn whole_tiles_address_every_level_where_it_was_written() {
    let t = tile(6, 37);
    let mut c = config(64 << 20, 1 << 30);
    c.scheme = Scheme::WholeTile;
    let mut m = Manager::new(vec![t.clone()], c);
    let first = m.plan_frame(0, None, &[req(0, 0)], true);
    let dst = |part: Part| {
        first
            .uploads
            .iter()
            .find(|u| u.part == part)
            .map(|u| u.dst)
            .unwrap_or_else(|| panic!("{part:?} not uploaded"))
    };
    let g0 = first.grants[0];
    for j in 0..=t.finest() {
        assert_eq!(
            dst(Part::Positions(j)),
            g0.vertex_offset + t.positions_before(j)
        );
    }
    // Nothing overlaps: the uploads, sorted, are disjoint and inside the chunk.
    let mut spans: Vec<(u64, u64)> = first
        .uploads
        .iter()
        .map(|u| (u.dst, u.dst + u.bytes))
        .collect();
    spans.sort();
    assert!(spans.windows(2).all(|w| w[0].1 <= w[1].0), "{spans:?}");
    let (start, size) = m.chunk_of(0).expect("resident");
    assert!(spans[0].0 >= start && spans.last().unwrap().1 <= start + size);
    for (f, level) in (1..=t.finest()).rev().chain(0..3).enumerate() {
        let f = f as u64 + 1;
        let p = m.plan_frame(f, Some(f - 1), &[req(0, level)], true);
        let g = p.grants[0];
        assert_eq!((g.level, p.uploads.len()), (Some(level), 0));
        assert_eq!(g.index_offset, dst(Part::Indices(level)));
        assert_eq!(g.index_offset % 4, 0);
    }
    m.check().unwrap();
}

#[test]
fn the_comparison_schemes_account_as_described() {
    let t = tile(5, 100);
    let run = |scheme| {
        let mut c = config(64 << 20, 1 << 30);
        c.scheme = scheme;
        let mut m = Manager::new(vec![t.clone()], c);
        let mut sent = 0;
        for (f, level) in [1u32, 3, 4].into_iter().enumerate() {
            let f = f as u64;
            let p = m.plan_frame(f, f.checked_sub(1), &[req(0, level)], true);
            assert_eq!(p.grants[0].level, Some(level));
            sent += p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
        }
        sent
    };
    let blocks = |a: u32, b: u32| (a..=b).map(|j| t.block_bytes(j)).sum::<u64>();
    let idx = |l: usize| t.levels[l].indices;
    assert_eq!(run(Scheme::WholeTile), t.whole());
    assert_eq!(
        run(Scheme::Progressive),
        blocks(0, 4) + idx(0) + idx(1) + idx(3) + idx(4)
    );
    assert_eq!(
        run(Scheme::PerLevel),
        blocks(0, 0)
            + blocks(0, 1)
            + blocks(0, 3)
            + blocks(0, 4)
            + idx(0)
            + idx(1)
            + idx(3)
            + idx(4)
    );
}

#[test]
fn plans_without_uploads_draw_only_what_is_resident() {
    let t = tile(4, 100);
    let mut m = Manager::new(vec![t.clone(), t], config(64 << 20, 1 << 30));
    m.plan_frame(0, None, &[req(0, 2)], true);
    let p = m.plan_frame(1, Some(0), &[req(0, 3), req(1, 1)], false);
    assert!(p.uploads.is_empty() && p.moves.is_empty());
    assert_eq!(p.grants[0].level, Some(2));
    assert_eq!(p.grants[1].level, None);
}

/// Byte ranges a grant's draw reads: positions and morph rows of blocks `0..=level`, and the
/// index array.
fn reads(m: &Manager, g: &Grant) -> Vec<(u64, u64)> {
    let Some(l) = g.level else { return vec![] };
    let t = m.tile_cost(g.tile);
    vec![
        (g.vertex_offset, g.vertex_offset + t.positions_before(l + 1)),
        (g.morph_offset, g.morph_offset + t.morph_before(l + 1)),
        (
            g.index_offset,
            g.index_offset + t.levels[l as usize].indices,
        ),
    ]
}

fn overlaps(a: (u64, u64), b: (u64, u64)) -> bool {
    a.0 < b.1 && b.0 < a.1 && a.0 < a.1 && b.0 < b.1
}

#[test]
fn prefetched_tiles_are_hits_when_drawn_and_waste_when_evicted_unused() {
    let t = tile(6, 60);
    let tiles = vec![t.clone(); 4];
    let mut m = Manager::new(tiles.clone(), config(64 << 20, 1 << 30));
    // Frame 0 draws tile 0 at level 2; tile 1 is predicted at level 3, and so is tile 0.
    let mut p = m.plan_frame(0, None, &[req(0, 2)], true);
    let drawn = p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
    let reads0 = reads(&m, &p.grants[0]);
    m.prefetch(&mut p, &[req(1, 3), req(0, 3)]);
    let tile1: u64 = (0..=3).map(|j| t.block_bytes(j)).sum::<u64>() + t.levels[3].indices;
    // Tile 0 (drawn) gets block 3 and level 3's index array as a spare beside level 2's, which
    // this frame still draws.
    let tile0 = t.block_bytes(3) + t.levels[3].indices;
    assert_eq!(p.stats.prefetch_bytes, tile1 + tile0);
    assert_eq!(
        p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices,
        drawn + tile1 + tile0
    );
    assert_eq!(m.resident_levels(0), Some((Some(3), Some(2))));
    assert_eq!(m.resident_levels(1), Some((Some(3), Some(3))));
    let spare = *p
        .uploads
        .iter()
        .find(|u| u.tile == 0 && u.part == Part::Indices(3))
        .expect("the spare is sent");
    for r in &reads0 {
        assert!(!overlaps((spare.dst, spare.dst + spare.bytes), *r));
    }
    m.check().unwrap();
    // Frame 1: both want 3 and need nothing; tile 0 draws the spare where it was sent. Three
    // prefetches pay off: tile 1's level, tile 0's block and tile 0's index array.
    let p = m.plan_frame(1, Some(0), &[req(1, 3), req(0, 3)], true);
    assert_eq!(p.stats.prefetch_hits, 3);
    assert_eq!(
        p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices,
        0
    );
    assert_eq!(p.stats.hits, 2);
    assert_eq!(p.grants[1].index_offset, spare.dst);
    m.check().unwrap();
    // Counted once.
    let p = m.plan_frame(2, Some(1), &[req(1, 3), req(0, 3)], true);
    assert_eq!(p.stats.prefetch_hits, 0);

    // Waste: a pool that holds two tiles at level 5; tile 2 is prefetched, never drawn, and
    // evicted when tiles 0 and 3 need the room.
    let need = t.need(5).next_multiple_of(256);
    let two_chunks = ClassPlan {
        sizes: vec![need],
        counts: vec![2],
        votes: vec![0],
    };
    let c = Config {
        prefetch_free: 0.0,
        ..config(2 * need, 1 << 30)
    };
    let mut m = Manager::with_classes(tiles, c, two_chunks);
    m.plan_frame(0, None, &[req(0, 5)], true);
    let mut p = m.plan_frame(1, Some(0), &[req(0, 5)], true);
    m.prefetch(&mut p, &[req(2, 5)]);
    let sent = p.stats.prefetch_bytes;
    assert!(sent > 0);
    let mut wasted = 0;
    for f in 2..6 {
        let p = m.plan_frame(f, Some(f - 1), &[req(0, 5), req(3, 5)], true);
        wasted += p.stats.prefetch_wasted_bytes;
        assert_eq!(p.stats.prefetch_hits, 0);
    }
    assert_eq!(
        m.resident_levels(2),
        None,
        "the pool holds two tiles at level 5"
    );
    assert_eq!(wasted, sent);
}

/// A tile refined a level a frame, each predicted a frame ahead: once the first array is there,
/// no frame sends anything for the level it draws (the index arrays alternate between the two
/// ends of the index region, moving to larger chunks as the tile outgrows its own), and a spare
/// replaced before it is drawn counts as waste.
#[test]
fn spare_index_arrays_make_each_refinement_arrive_ahead_of_need() {
    let t = tile(7, 60);
    let mut m = Manager::new(vec![t.clone(); 2], config(64 << 20, 1 << 30));
    let mut sent_ahead = 0;
    for f in 0..7u32 {
        let mut p = m.plan_frame(
            u64::from(f),
            u64::from(f).checked_sub(2),
            &[req(0, f)],
            true,
        );
        assert_eq!(p.grants[0].level, Some(f));
        let now = p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
        if f > 0 {
            assert_eq!(now, 0, "frame {f} waited for its level");
        }
        m.prefetch(&mut p, &[req(0, f + 1)]);
        sent_ahead += p.stats.prefetch_bytes;
        assert_eq!(p.stats.prefetch_wasted_bytes, 0);
        m.check().unwrap();
    }
    let every_level: u64 = (0..7)
        .map(|j| t.block_bytes(j) + t.levels[j as usize].indices)
        .sum();
    assert_eq!(
        sent_ahead,
        every_level - t.block_bytes(0) - t.levels[0].indices
    );
    // Tile 1 drawn at 2 with a spare for 3; then predicted at 4: the spare for 3 is replaced
    // unused.
    let mut p = m.plan_frame(7, Some(5), &[req(1, 2)], true);
    m.prefetch(&mut p, &[req(1, 3)]);
    assert_eq!(m.resident_levels(1), Some((Some(3), Some(2))));
    let mut p = m.plan_frame(8, Some(6), &[req(1, 2)], true);
    m.prefetch(&mut p, &[req(1, 4)]);
    assert_eq!(p.stats.prefetch_wasted_bytes, t.levels[3].indices);
    assert_eq!(
        p.stats.prefetch_bytes,
        t.block_bytes(4) + t.levels[4].indices
    );
    m.check().unwrap();
}

#[test]
fn prefetching_stops_at_the_free_share_and_the_budget() {
    let t = tile(6, 60);
    let tiles = vec![t.clone(); 8];
    let level0 = t.block_bytes(0) + t.levels[0].indices;
    let candidates: Vec<Request> = (1..8).map(|i| req(i, 0)).collect();
    // Room for exactly two tiles' level 0 in the budget left after drawing tile 0.
    let mut m = Manager::new(tiles.clone(), config(64 << 20, 3 * level0));
    let mut p = m.plan_frame(0, None, &[req(0, 0)], true);
    m.prefetch(&mut p, &candidates);
    assert_eq!(p.stats.prefetch_bytes, 2 * level0);
    // A pool that must keep every chunk free: nothing.
    let mut m = Manager::new(
        tiles,
        Config {
            prefetch_free: 1.0,
            ..config(64 << 20, 1 << 30)
        },
    );
    let mut p = m.plan_frame(0, None, &[req(0, 0)], true);
    m.prefetch(&mut p, &candidates);
    assert_eq!(p.stats.prefetch_bytes, 0);
}

/// `prefetch_while` asks before each candidate and takes none once told to stop (the renderer's
/// `--prefetch-ms` deadline): allowed two asks, two tiles; never allowed, none; always allowed,
/// as `prefetch` (the control: the budget, not the deadline, stops it there).
#[test]
fn prefetching_stops_when_its_time_is_up() {
    let t = tile(6, 60);
    let tiles = vec![t.clone(); 8];
    let level0 = t.block_bytes(0) + t.levels[0].indices;
    let candidates: Vec<Request> = (1..8).map(|i| req(i, 0)).collect();
    let sent = |asks: usize| {
        let mut m = Manager::new(tiles.clone(), config(64 << 20, 1 << 30));
        let mut p = m.plan_frame(0, None, &[req(0, 0)], true);
        let mut left = asks;
        m.prefetch_while(&mut p, &candidates, || {
            left = left.saturating_sub(1);
            left > 0 || asks == usize::MAX
        });
        p.stats.prefetch_bytes
    };
    assert_eq!(sent(3), 2 * level0);
    assert_eq!(sent(0), 0);
    assert_eq!(sent(usize::MAX), 7 * level0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// On random flights with random budgets, weights and frames in flight: the bookkeeping
    /// holds, resident bytes stay within the pool, every drawn tile is drawn at a level whose
    /// data was sent, and nothing a frame in flight may read is written by the CPU or reused;
    /// with blocks sent as positions or as streams decoded on the GPU.
    #[test]
    fn random_traces_keep_the_invariants(
        scales in proptest::collection::vec(20u64..400, 2..14),
        frames in proptest::collection::vec(
            proptest::collection::vec((0u32..14, 0u32..7), 0..10), 1..50),
        pool_kib in 64u64..4096,
        upload in 0u64..400_000,
        in_flight in 1u64..4,
        weight in 0.0f64..4.0,
        victim in 0usize..3,
        prefetch in any::<bool>(),
        noise in proptest::collection::vec((0u32..14, 0u32..7), 0..4),
        built in any::<bool>(),
        streamed in any::<bool>(),
    ) {
        let mut tiles: Vec<TileCost> = scales.iter().map(|&s| tile(7, s)).collect();
        if streamed {
            // Blocks decoded on the GPU from streams a third their size.
            for l in tiles.iter_mut().flat_map(|t| &mut t.levels) {
                l.stream = Some(l.positions / 3 + 1);
            }
        }
        let n = tiles.len() as u32;
        let mut c = config(pool_kib << 10, upload);
        c.weight = weight;
        c.victim = [Victim::Mixture, Victim::Lru, Victim::TightestFit][victim];
        if built {
            c.index_arrays = IndexArrays::Built;
        }
        let mut m = Manager::new(tiles.clone(), c);
        prop_assert!(m.pool_bytes() <= pool_kib << 10);
        // What each frame read, by frame.
        let mut read: Vec<Vec<(u64, u64)>> = Vec::new();
        // What each frame's in-pool copies wrote, by frame (they run when the GPU gets there).
        let mut copied: Vec<Vec<(u64, u64)>> = Vec::new();
        // Data each tile has received, per level: (blocks, index level).
        for (f, frame) in frames.iter().enumerate() {
            let f = f as u64;
            let completed = f.checked_sub(in_flight);
            let mut seen = std::collections::HashSet::new();
            let requests: Vec<Request> = frame
                .iter()
                .filter(|(t, _)| seen.insert(t % n))
                .map(|&(t, l)| req(t % n, l))
                .collect();
            let new = new_tiles(&m, &requests);
            let p = m.plan_frame(f, completed, &requests, true);
            m.check().map_err(TestCaseError::fail)?;
            prop_assert!(p.stats.resident_bytes <= m.pool_bytes());
            prop_assert_eq!(p.grants.len(), requests.len());
            // Writes by the CPU now (uploads not flagged) and in-pool copies must not touch
            // what frames in flight read.
            let flying = completed.map_or(0, |c| c + 1) as usize..read.len();
            for u in &p.uploads {
                let w = (u.dst, u.dst + u.bytes);
                for r in read[flying.clone()].iter().flatten() {
                    prop_assert!(
                        u.gpu_ordered() || !overlaps(w, *r),
                        "frame {f}: upload {u:?} overwrites {r:?} read by a frame in flight"
                    );
                }
            }
            for mv in &p.moves {
                let w = (mv.dst, mv.dst + mv.bytes);
                for r in read[flying.clone()].iter().flatten() {
                    prop_assert!(!overlaps(w, *r), "frame {f}: move {mv:?} over {r:?}");
                }
            }
            // Every drawn level is fully held by its tile.
            for g in &p.grants {
                if let Some(l) = g.level {
                    let (blocks, index) = m.resident_levels(g.tile).unwrap();
                    prop_assert!(blocks.is_some_and(|b| b >= l));
                    prop_assert_eq!(index, Some(l));
                }
            }
            // Budget: beyond it only for presence or a step alone.
            check_budget(&p, &new, upload).map_err(|e| TestCaseError::fail(format!("frame {f}: {e}")))?;
            let sent = p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
            let drawn: Vec<(u64, u64)> = p.grants.iter().flat_map(|g| reads(&m, g)).collect();
            let mut p = p;
            if prefetch {
                // The next frame's requests (a perfect prediction) and some noise.
                let next = frames.get(f as usize + 1).cloned().unwrap_or_default();
                let candidates: Vec<Request> = next
                    .iter()
                    .chain(&noise)
                    .map(|&(t, l)| req(t % n, l))
                    .collect();
                let (uploads, moves, evictions) = (p.uploads.len(), p.moves.len(), p.stats.evictions);
                m.prefetch(&mut p, &candidates);
                m.check().map_err(TestCaseError::fail)?;
                prop_assert_eq!(p.stats.evictions, evictions, "prefetch evicted");
                // Drawn tiles keep their level (a tile may have moved to a larger chunk: this
                // frame reads the old one, which the checks below and the later frames'
                // checks of reads in flight keep untouched).
                for g in &p.grants {
                    if let Some(l) = g.level {
                        prop_assert_eq!(m.resident_levels(g.tile).unwrap().1, Some(l));
                    }
                }
                for u in &p.uploads[uploads..] {
                    let w = (u.dst, u.dst + u.bytes);
                    for r in &drawn {
                        prop_assert!(!overlaps(w, *r), "prefetch {u:?} over this frame's {r:?}");
                    }
                    for r in read[flying.clone()].iter().flatten() {
                        prop_assert!(u.gpu_ordered() || !overlaps(w, *r), "prefetch {u:?} over {r:?}");
                    }
                }
                for mv in &p.moves[moves..] {
                    let w = (mv.dst, mv.dst + mv.bytes);
                    for r in drawn.iter().chain(read[flying.clone()].iter().flatten()) {
                        prop_assert!(!overlaps(w, *r), "prefetch move {mv:?} over {r:?}");
                    }
                }
                // Prefetching spends only what the frame left of the budget.
                let sent_after = p.stats.upload_bytes_blocks + p.stats.upload_bytes_indices;
                prop_assert_eq!(sent_after - sent, p.stats.prefetch_bytes);
                prop_assert!(sent_after <= upload.max(sent));
            }
            // CPU writes never race a copy not yet run (this frame's or one in flight).
            let moved: Vec<(u64, u64)> = p.moves.iter().map(|mv| (mv.dst, mv.dst + mv.bytes)).collect();
            for u in p.uploads.iter().filter(|u| !u.gpu_ordered()) {
                let w = (u.dst, u.dst + u.bytes);
                for c in copied[flying.clone()].iter().flatten().chain(&moved) {
                    prop_assert!(!overlaps(w, *c), "frame {f}: upload {u:?} races the copy to {c:?}");
                }
            }
            // Staged uploads run after the frame's copies: a copy must not read what one of
            // them writes (it would carry the old bytes).
            for mv in &p.moves {
                for u in p.uploads.iter().filter(|u| u.gpu_ordered()) {
                    prop_assert!(
                        !overlaps((mv.src, mv.src + mv.bytes), (u.dst, u.dst + u.bytes)),
                        "frame {f}: move {mv:?} reads before {u:?} writes"
                    );
                }
            }
            // Writes on the GPU (builds, staged copies) run after every CPU write of the frame:
            // a CPU write planned after one must not land where it does (a chunk given back
            // and taken again within the frame), or the GPU would overwrite it.
            for (i, a) in p.uploads.iter().enumerate().filter(|(_, u)| u.gpu_ordered()) {
                for b in p.uploads[i + 1..].iter().filter(|u| !u.gpu_ordered()) {
                    prop_assert!(
                        !overlaps((a.dst, a.dst + a.bytes), (b.dst, b.dst + b.bytes)),
                        "frame {f}: {b:?} written now, then overwritten by {a:?}"
                    );
                }
            }
            // One copy command: no region is both read and written.
            for a in &p.moves {
                for b in &p.moves {
                    prop_assert!(
                        !overlaps((a.src, a.src + a.bytes), (b.dst, b.dst + b.bytes)),
                        "frame {f}: move {a:?} reads what {b:?} writes"
                    );
                }
            }
            // A build reads its tile's blocks and writes its array when the frame runs: both
            // count as the frame's reads and GPU writes for the frames after it.
            let mut drawn = drawn;
            let mut moved = moved;
            // So do the sources of the frame's in-pool copies.
            drawn.extend(p.moves.iter().map(|mv| (mv.src, mv.src + mv.bytes)));
            for u in p.uploads.iter().filter(|u| u.built) {
                let Part::Indices(level) = u.part else { unreachable!("only arrays are built") };
                let blocks = tiles[u.tile as usize].positions_before(level + 1);
                drawn.push((u.chunk, u.chunk + blocks));
                moved.push((u.dst, u.dst + u.bytes));
            }
            copied.push(moved);
            read.push(drawn);
        }
    }
}

/// A manager whose costs come from a source plans exactly as one given every tile's costs
/// where the set has at most `costs::SAMPLE_TILES` tiles: the same classes and counts, and the
/// same frames. The source is asked for no tile before the plan and, after it, only for the
/// tiles a frame requests.
#[test]
fn costs_from_a_source_plan_a_small_set_as_costs_given_whole() {
    use std::cell::Cell;
    use std::rc::Rc;
    let costs: Vec<TileCost> = (0..300)
        .map(|t| tile(5 + t % 4, 20 + 7 * u64::from(t % 13)))
        .collect();
    for pool in [2 << 20, 40 << 20, 1 << 34] {
        let given = Manager::new(costs.clone(), config(pool, 64 << 10));
        let asked = Rc::new(Cell::new(0u32));
        let (counted, held) = (Rc::clone(&asked), costs.clone());
        let source = move |t: TileId| {
            counted.set(counted.get() + 1);
            held[t as usize].clone()
        };
        let from = Manager::from_source(
            costs.len(),
            Box::new(source),
            config(pool, 64 << 10),
            costs::SAMPLE_TILES,
        );
        assert_eq!(from.classes(), given.classes(), "pool {pool}");
        assert_eq!(asked.get(), 300, "the plan reads every tile of a small set");
        let (mut a, mut b) = (given, from);
        for frame in 0..6u64 {
            let requests: Vec<Request> = (0..40)
                .map(|k| req(((frame * 37 + k * 11) % 300) as TileId, (k % 6) as u32))
                .collect();
            let done = frame.checked_sub(1);
            let (pa, pb) = (
                a.plan_frame(frame, done, &requests, true),
                b.plan_frame(frame, done, &requests, true),
            );
            assert_eq!(pa.grants, pb.grants, "frame {frame}");
            assert_eq!(pa.uploads.len(), pb.uploads.len(), "frame {frame}");
        }
    }
}

/// Above `costs::SAMPLE_TILES` tiles the plan reads a stride sample, each sampled tile standing
/// for `stride` tiles, and a tile outside the sample is read when a frame first requests it.
/// A set of 20,000 tiles of fifteen kinds in a period of 15 tiles gets the classes of the plan
/// over every tile, and votes within a fifth of its (every `stride`-th tile alone would see
/// one kind in three: `costs::sample`).
#[test]
fn a_large_set_is_planned_from_a_sample_and_read_as_requested() {
    use std::cell::RefCell;
    use std::rc::Rc;
    let kind = |t: u32| tile(4 + t % 3, 30 + 20 * u64::from(t % 5));
    let n = 20_000;
    let asked = Rc::new(RefCell::new(Vec::new()));
    let log = Rc::clone(&asked);
    let source = move |t: TileId| {
        log.borrow_mut().push(t);
        kind(t)
    };
    let cfg = config(64 << 20, 256 << 10);
    let mut m = Manager::from_source(n, Box::new(source), cfg, costs::SAMPLE_TILES);
    let (sample, stride) = costs::sample(n, costs::SAMPLE_TILES);
    assert_eq!((sample.len(), stride), (1000, 20));
    assert_eq!(
        *asked.borrow(),
        sample,
        "the plan reads the sample alone, once each"
    );
    let whole = Manager::new((0..n as u32).map(kind).collect(), cfg);
    assert_eq!(m.classes().sizes, whole.classes().sizes);
    let (mine, all) = (&m.classes().votes, &whole.classes().votes);
    for (a, b) in mine.iter().zip(all) {
        assert!(a.abs_diff(*b) * 5 <= *b, "votes {mine:?} against {all:?}");
    }
    assert!(m.pool_bytes() <= cfg.pool_bytes);
    // A tile the sample skipped is read when first requested, and drawn.
    let outside = 12_345;
    assert!(!sample.contains(&outside));
    let p = m.plan_frame(0, None, &[req(outside, 2)], true);
    assert!(p.grants[0].level.is_some());
    assert_eq!(asked.borrow().last(), Some(&outside));
}

/// The staging cap holds a frame's new tiles back once their level 0 would pass it: the tiles
/// held back are missing this frame and come in the next. The control: without a cap the same
/// frame takes every tile in.
#[test]
fn the_staging_cap_holds_new_tiles_back_to_a_later_frame() {
    let costs: Vec<TileCost> = (0..20).map(|_| tile(4, 100)).collect();
    let presence = costs[0].block_bytes(0) + costs[0].levels[0].indices;
    let requests: Vec<Request> = (0..20).map(|t| req(t, 0)).collect();
    let mut free = Manager::new(costs.clone(), config(64 << 20, 0));
    let p = free.plan_frame(0, None, &requests, true);
    assert_eq!(p.stats.tiles_missing, 0, "the control takes every tile in");
    let mut capped = Manager::new(costs, config(64 << 20, 0));
    capped.set_staging_cap(5 * presence + presence / 2);
    let p = capped.plan_frame(0, None, &requests, true);
    let sent: u64 = p.uploads.iter().map(Upload::sent).sum();
    assert_eq!((p.stats.tiles_missing, sent), (15, 5 * presence));
    let p = capped.plan_frame(1, Some(0), &requests, true);
    assert_eq!(p.stats.tiles_missing, 10, "five more the next frame");
}
