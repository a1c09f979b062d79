//! The residency policy: which level each visible tile gets this frame, what to upload, what to
//! move and what to evict. Plain Rust, no GPU: [`Manager::plan_frame`] takes the frame's
//! requests (visible tiles front to back with their wanted levels) and returns a [`FramePlan`].

use crate::classes::ClassPlan;
use crate::cost::{align, Layout, TileCost};
use crate::costs::{CostSource, Costs};
use crate::lru::LruLists;

pub type TileId = u32;

/// How levels travel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheme {
    /// The paper's: refining from `l` to `g` sends blocks `l+1..=g` and level `g`'s index array.
    Progressive,
    /// Every level change sends blocks `0..=g` again with the index array (no reuse of coarser
    /// blocks). Accounting only (the simulator's comparison).
    PerLevel,
    /// A tile's first use sends all its blocks and index arrays, whatever the budget (the
    /// renderer's old scheme). Accounting only.
    WholeTile,
}

/// Where index arrays come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IndexArrays {
    /// Copied from the file like the blocks: they cost upload budget.
    #[default]
    Sent,
    /// Built on the GPU from the tile's resident blocks (the renderer's compute pass, see
    /// `renderer/src/vulkan/indices.rs`): they take the same pool space but cross no bus, so
    /// the upload budget pays for blocks only.
    Built,
}

/// How a victim is chosen when no free chunk fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Victim {
    /// The paper's mixture: the oldest chunk of each class large enough is a candidate; the
    /// one with the best `ln(1 + age) - weight * log2(chunk / need)` goes.
    Mixture,
    /// The least recently used chunk of any class large enough.
    Lru,
    /// The least recently used chunk of the smallest class that has one.
    TightestFit,
    /// The chunk whose tile is used again farthest in the future (needs an oracle; the
    /// simulator's reference).
    Belady,
}

#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Bytes of device memory for the pool.
    pub pool_bytes: u64,
    /// Bytes uploaded per frame at most (see [`Manager::plan_frame`] for the two exceptions).
    pub upload_budget: u64,
    /// Mixture weight: how many e-folds of age one doubling of wasted space is worth.
    pub weight: f64,
    /// Growth ratio of the size classes.
    pub class_ratio: f64,
    pub scheme: Scheme,
    pub victim: Victim,
    /// How many levels finer than wanted a tile may stay drawn before its index array is
    /// replaced by the coarser one. Finer is always within tau; replacing costs an upload.
    pub downgrade_slack: u32,
    /// [`Manager::prefetch`] runs while at least this share of the chunks is free, and stops
    /// before taking the pool below it.
    pub prefetch_free: f64,
    pub index_arrays: IndexArrays,
}

/// The default per-frame upload budget: 4 MiB, ~240 MB/s at 60 frames per second, a small
/// share of any PCIe link, and a few milliseconds of memcpy on lavapipe.
pub const DEFAULT_UPLOAD_BUDGET: u64 = 4 << 20;

/// The default downgrade slack (measured with `memsim`, see bench/README.md).
pub const DEFAULT_DOWNGRADE_SLACK: u32 = 0;

/// The default mixture weight (measured with `memsim`, see bench/README.md).
pub const DEFAULT_WEIGHT: f64 = 1.0;

/// The default share of free chunks below which nothing is prefetched.
pub const DEFAULT_PREFETCH_FREE: f64 = 0.1;

impl Default for Config {
    fn default() -> Self {
        Config {
            pool_bytes: 256 << 20,
            upload_budget: DEFAULT_UPLOAD_BUDGET,
            weight: DEFAULT_WEIGHT,
            class_ratio: 2.0,
            scheme: Scheme::Progressive,
            victim: Victim::Mixture,
            downgrade_slack: DEFAULT_DOWNGRADE_SLACK,
            prefetch_free: DEFAULT_PREFETCH_FREE,
            index_arrays: IndexArrays::Sent,
        }
    }
}

/// One visible tile this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Request {
    pub tile: TileId,
    pub wanted: u32,
}

/// A part of a tile's data, as the file stores it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    Positions(u32),
    Morph(u32),
    Indices(u32),
}

/// Copy `bytes` of `part` of `tile` to pool offset `dst`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Upload {
    pub tile: TileId,
    pub part: Part,
    pub dst: u64,
    pub bytes: u64,
    /// The destination may be read by a frame still in flight (an index region rewritten):
    /// it must be written by a copy ordered after those frames, not by the CPU now.
    pub in_flight: bool,
    /// Pool offset of the chunk it goes into (where the tile's block 0 positions start: an
    /// index array is built from the blocks there).
    pub chunk: u64,
    /// An index array built on the GPU from the tile's blocks ([`IndexArrays::Built`]):
    /// nothing is sent, and it is written in the frame's command buffer after the copies.
    pub built: bool,
    /// Positions sent as the level's compact stream of this many bytes ([`LevelCost::stream`])
    /// and decoded on the GPU into `bytes` at `dst`, after the copies and before the builds.
    pub stream: Option<u64>,
}

impl Upload {
    /// Bytes that cross the bus (what the upload budget counts).
    pub fn sent(&self) -> u64 {
        if self.built {
            0
        } else if let Some(stream) = self.stream {
            stream
        } else {
            self.bytes
        }
    }

    /// Written on the GPU in the frame's command buffer (after its in-pool copies), not by
    /// the CPU when planned: a staged copy, a built index array, a decoded block.
    pub fn gpu_ordered(&self) -> bool {
        self.in_flight || self.built || self.stream.is_some()
    }
}

/// The index arrays a frame builds on the GPU, in plan order. A build whose destination a
/// later build of the same frame overlaps is left out: the later array is the one drawn (a
/// tile granted its level 0 and its wanted level in one frame), and two builds must not write
/// the same indices.
pub fn gpu_builds(uploads: &[Upload]) -> Vec<&Upload> {
    let mut kept: Vec<&Upload> = Vec::new();
    for u in uploads.iter().rev().filter(|u| u.built) {
        let overlaps = |k: &&Upload| u.dst < k.dst + k.bytes && k.dst < u.dst + u.bytes;
        if !kept.iter().any(overlaps) {
            kept.push(u);
        }
    }
    kept.reverse();
    kept
}

/// A copy inside the pool (a tile moving to a larger chunk).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Move {
    pub tile: TileId,
    pub src: u64,
    pub dst: u64,
    pub bytes: u64,
}

/// What to draw for one request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grant {
    pub tile: TileId,
    pub wanted: u32,
    /// The level drawn; None when the tile has nothing resident (counted as missing).
    pub level: Option<u32>,
    /// Pool byte offset of block 0's positions (the draw's `vertexOffset` times 4).
    pub vertex_offset: u64,
    /// Pool byte offset of block 0's morph rows (blocks follow in order, each padded to 4).
    pub morph_offset: u64,
    /// Pool byte offset of the level's index array.
    pub index_offset: u64,
    pub index_width: u32,
}

/// One frame's counters (the log's columns).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    pub hits: u64,
    pub misses: u64,
    pub tiles_coarser: u64,
    pub tiles_missing: u64,
    pub upload_bytes_blocks: u64,
    /// Index array bytes sent (0 when they are built on the GPU).
    pub upload_bytes_indices: u64,
    /// Index arrays built on the GPU this frame, and their bytes (written in GPU memory,
    /// not sent).
    pub index_builds: u64,
    pub index_build_bytes: u64,
    /// Of `upload_bytes_indices`: index arrays sent to draw a tile coarser than it was drawn
    /// (its blocks are resident; a coarser level needs only its index array). This is what
    /// `Config::downgrade_slack` trades for triangles.
    pub upload_bytes_coarser: u64,
    /// Bytes still needed to bring every visible tile to its wanted level.
    pub uploads_deferred_bytes: u64,
    /// Bytes uploaded beyond the budget (presence of new tiles, or one step larger than it).
    pub upload_overshoot_bytes: u64,
    pub evictions: u64,
    pub chunk_moves: u64,
    pub chunk_move_bytes: u64,
    pub chunks_free: u64,
    pub resident_bytes: u64,
    /// Bytes of tile data held (resident_bytes less the slack of tight fits).
    pub used_bytes: u64,
    /// Of the uploads: bytes sent speculatively by [`Manager::prefetch`].
    pub prefetch_bytes: u64,
    /// Prefetches drawn this frame for the first time: a tile's prefetched blocks (once per
    /// prefetch) and its spare index array count apart.
    pub prefetch_hits: u64,
    /// Prefetched bytes evicted or overwritten this frame before anything drew them.
    pub prefetch_wasted_bytes: u64,
}

#[derive(Clone, Debug, Default)]
pub struct FramePlan {
    pub grants: Vec<Grant>,
    pub uploads: Vec<Upload>,
    pub moves: Vec<Move>,
    pub stats: Stats,
}

#[derive(Clone, Copy, Debug)]
struct Chunk {
    class: usize,
    offset: u64,
    owner: Option<TileId>,
    /// The last frame that requested the owner (or moved it out): the chunk may be read by
    /// that frame, so it is not reused before that frame completes.
    last_used: u64,
    /// The last frame that drew from it, if any.
    drawn: Option<u64>,
    /// The last frame whose in-pool copies wrote into it (a tile moves once per frame: the
    /// copies of one frame are one command, whose regions must not chain).
    copied_in: Option<u64>,
    /// The last frame whose commands write into it on the GPU (an index array built, a block
    /// decoded), besides its in-pool copies.
    gpu_written_in: Option<u64>,
}

#[derive(Clone, Copy, Debug)]
struct Resident {
    chunk: usize,
    layout: Layout,
    /// Blocks `0..=b` are in the chunk.
    blocks: Option<u32>,
    /// The level of the index array drawn.
    index: Option<u32>,
    /// Where in the chunk the drawn index array starts (the index region's start unless it was
    /// a spare).
    index_at: u64,
    /// A second index array, prefetched and not drawn yet: its level and where it starts in
    /// the chunk. It lies in the index region (which runs to the chunk's end) apart from the
    /// drawn one, so the next level's array travels ahead of need while this one is drawn.
    spare: Option<(u32, u64)>,
    /// WholeTile: every level's index array is there.
    whole: bool,
    /// Data prefetched and not drawn yet.
    speculative: Option<Speculation>,
}

/// What a prefetch sent for a tile: blocks `from..` (and any index array), `bytes` in all. It is
/// a hit once the tile is drawn at level `from` or finer.
#[derive(Clone, Copy, Debug)]
struct Speculation {
    from: u32,
    bytes: u64,
}

/// The chunk pool and who holds what.
pub struct Manager {
    config: Config,
    /// Per tile: its costs, and per level the bytes a chunk needs to hold it (the scheme's
    /// view); given at start or read as first needed.
    tiles: Costs,
    classes: ClassPlan,
    /// Bytes a frame's uploads may stage at most (the renderer's staging memory): a new
    /// tile's level 0 that would pass it waits for a later frame.
    staging_cap: u64,
    chunks: Vec<Chunk>,
    /// Per class: free chunks nobody may still read, and free chunks waiting for a frame.
    free: Vec<Vec<usize>>,
    retiring: Vec<usize>,
    /// Per class: owned chunks, least recently used first.
    lru: LruLists,
    resident: Vec<Option<Resident>>,
    frame: u64,
    completed: Option<u64>,
    /// For Belady: the frame at which a tile is next requested after the current one.
    oracle: Option<Box<dyn Fn(TileId, u64) -> u64>>,
    /// Prefetching: chunks come from the free lists only, never from a victim.
    speculating: bool,
    /// Chunks with an owner (kept as they change hands: prefetching asks once per candidate).
    owned: usize,
}

impl Manager {
    /// Plans the pool for `tiles` (size classes and counts from their size histogram).
    pub fn new(tiles: Vec<TileCost>, config: Config) -> Manager {
        Self::planned(Costs::given(tiles, config.scheme), config)
    }

    /// Plans the pool for `count` tiles whose costs `source` gives the first time the manager
    /// needs them: size classes and counts from the histogram of a sample of about `at_most`
    /// of them ([`crate::costs::sample`]; every tile of a set of up to `at_most`, as
    /// [`Manager::new`] plans; [`crate::costs::SAMPLE_TILES`] by default). A tile of a larger
    /// set that outgrows every class the sample planned is drawn at the finest level that fits
    /// one (counted as coarser).
    pub fn from_source(
        count: usize,
        source: CostSource,
        config: Config,
        at_most: usize,
    ) -> Manager {
        Self::planned(
            Costs::from_source(count, source, config.scheme, at_most),
            config,
        )
    }

    /// The pool for `tiles`, its classes planned from the tiles' sample (all of them where
    /// their costs were given).
    fn planned(tiles: Costs, config: Config) -> Manager {
        let (sample, weight) = tiles.sample();
        let needs: Vec<&[u64]> = sample.iter().map(|&t| tiles.needs(t as usize)).collect();
        let classes = ClassPlan::weighted(&needs, weight, config.pool_bytes, config.class_ratio);
        Self::carved(tiles, config, classes)
    }

    /// Bytes a chunk needs for each tile and level under `scheme`.
    pub fn needs(tiles: &[TileCost], scheme: Scheme) -> Vec<Vec<u64>> {
        tiles
            .iter()
            .map(|t| crate::costs::needs_of(t, scheme))
            .collect()
    }

    /// A pool carved as `classes` says.
    pub fn with_classes(tiles: Vec<TileCost>, config: Config, classes: ClassPlan) -> Manager {
        let tiles = Costs::given(tiles, config.scheme);
        Self::carved(tiles, config, classes)
    }

    fn carved(tiles: Costs, config: Config, classes: ClassPlan) -> Manager {
        let mut chunks = Vec::new();
        let mut free = vec![Vec::new(); classes.sizes.len()];
        let mut offset = 0;
        for (class, (&size, &count)) in classes.sizes.iter().zip(&classes.counts).enumerate() {
            for _ in 0..count {
                free[class].push(chunks.len());
                chunks.push(Chunk {
                    class,
                    offset,
                    owner: None,
                    last_used: 0,
                    drawn: None,
                    copied_in: None,
                    gpu_written_in: None,
                });
                offset += size;
            }
        }
        // Hand out low offsets first.
        for f in &mut free {
            f.reverse();
        }
        let n = tiles.len();
        Manager {
            config,
            tiles,
            staging_cap: u64::MAX,
            lru: LruLists::new(classes.sizes.len(), chunks.len()),
            classes,
            chunks,
            free,
            retiring: Vec::new(),
            resident: vec![None; n],
            frame: 0,
            completed: None,
            oracle: None,
            speculating: false,
            owned: 0,
        }
    }

    /// Forgets every tile: the pool as at start, carved into the same classes, with the
    /// costs known so far kept.
    pub fn forget_all(&mut self) {
        let tiles = std::mem::replace(
            &mut self.tiles,
            Costs::given(Vec::new(), self.config.scheme),
        );
        let cap = self.staging_cap;
        *self = Manager::carved(tiles, self.config, self.classes.clone());
        self.staging_cap = cap;
    }

    /// Bytes of device memory the pool needs (allocate this once, at start).
    pub fn pool_bytes(&self) -> u64 {
        self.classes.bytes()
    }

    pub fn classes(&self) -> &ClassPlan {
        &self.classes
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Tile `tile`'s costs (read from the source if the manager had not needed them yet).
    pub fn tile_cost(&self, tile: TileId) -> &TileCost {
        &self.tiles[tile as usize]
    }

    /// The tiles the pool's classes were planned from, and how many tiles each stands for
    /// (every tile, each for itself, unless planned from a source: [`Manager::from_source`]).
    pub fn planned_from(&self) -> (Vec<TileId>, u64) {
        self.tiles.sample()
    }

    /// Caps the bytes a frame's uploads stage: past it, a new tile's level 0 waits for a
    /// later frame (the tile is missing until then). The staging memory's size, where it was
    /// sized from a sample of the tiles (`budget::staging_bound` over
    /// [`Manager::planned_from`]) rather than from every tile.
    pub fn set_staging_cap(&mut self, bytes: u64) {
        self.staging_cap = bytes;
    }

    /// Gives Belady's rule its knowledge of the future: `next(tile, frame)` is the first frame
    /// after `frame` that requests `tile` (u64::MAX if none).
    pub fn set_oracle(&mut self, next: Box<dyn Fn(TileId, u64) -> u64>) {
        self.oracle = Some(next);
    }

    /// The level resident for `tile` (blocks), and the level its index array is for.
    pub fn resident_levels(&self, tile: TileId) -> Option<(Option<u32>, Option<u32>)> {
        self.resident[tile as usize].map(|r| (r.blocks, r.index))
    }

    /// Pool offset of `tile`'s chunk and the layout of its data there.
    pub fn layout_of(&self, tile: TileId) -> Option<(u64, Layout)> {
        self.resident[tile as usize].map(|r| (self.chunks[r.chunk].offset, r.layout))
    }

    /// Pool offset of the index array `tile` is drawn with: the index region's start, or where a
    /// spare that became the drawn array lies.
    pub fn drawn_index_offset(&self, tile: TileId) -> Option<u64> {
        self.resident[tile as usize].map(|r| self.chunks[r.chunk].offset + r.index_at)
    }

    /// Pool offset and chunk size of the chunk `tile` owns.
    pub fn chunk_of(&self, tile: TileId) -> Option<(u64, u64)> {
        self.resident[tile as usize].map(|r| {
            let c = &self.chunks[r.chunk];
            (c.offset, self.classes.sizes[c.class])
        })
    }

    /// Plans frame `frame` (increasing by one each call). `completed` is the newest frame the
    /// GPU has finished (every frame up to it is done; later ones may be in flight): no chunk
    /// those may read is reused, and index regions they may read are marked
    /// [`Upload::in_flight`]. `requests` are the visible tiles, front to back.
    ///
    /// Order of work, all within the upload budget: first every visible tile without data gets
    /// a chunk (the tightest class for its *wanted* level) and its level 0, which is tiny, so
    /// no visible tile is missing (these may overshoot the budget); then, front to back, each
    /// tile is refined toward its wanted level as far as the budget left allows, moving to a
    /// larger chunk when it outgrows its own. A step larger than the whole budget is taken
    /// when nothing else was uploaded this frame, so every tile eventually gets there.
    /// `allow_uploads: false` plans draws of what is resident only (pre-recorded frames).
    pub fn plan_frame(
        &mut self,
        frame: u64,
        completed: Option<u64>,
        requests: &[Request],
        allow_uploads: bool,
    ) -> FramePlan {
        self.frame = frame;
        self.completed = completed;
        self.retire();
        let mut plan = FramePlan::default();
        let mut touched = vec![false; requests.len()];
        // Protect every requested tile from eviction this frame.
        for r in requests {
            if let Some(res) = self.resident[r.tile as usize] {
                self.touch(res.chunk);
            }
        }
        let mut spent = 0u64;
        if allow_uploads {
            // 1. Presence.
            for (k, r) in requests.iter().enumerate() {
                if self.resident[r.tile as usize].is_some() {
                    continue;
                }
                let wanted = r.wanted.min(self.tiles[r.tile as usize].finest());
                if self.staging_cap < u64::MAX
                    && spent.saturating_add(self.presence_bound(r.tile)) > self.staging_cap
                {
                    continue;
                }
                let Some(res) = self.admit(r.tile, wanted, &mut plan) else {
                    continue;
                };
                self.resident[r.tile as usize] = Some(res);
                let before = plan.uploads.len();
                if self.config.scheme == Scheme::WholeTile {
                    self.upload_whole(r.tile, &mut plan);
                } else {
                    self.upload_to(r.tile, 0, &mut plan);
                }
                let cost = bytes_since(&plan, before);
                spent += cost;
                plan.stats.upload_overshoot_bytes +=
                    spent.saturating_sub(self.config.upload_budget).min(cost);
                touched[k] = true;
            }
            // 2. Refinement, front to back.
            for (k, r) in requests.iter().enumerate() {
                let before = plan.uploads.len();
                self.refine(*r, spent, &mut plan);
                let cost = bytes_since(&plan, before);
                if cost > 0 {
                    touched[k] = true;
                    spent += cost;
                    plan.stats.upload_overshoot_bytes +=
                        spent.saturating_sub(self.config.upload_budget).min(cost);
                }
            }
        }
        // 3. Grants.
        for (k, r) in requests.iter().enumerate() {
            let wanted = r.wanted.min(self.tiles[r.tile as usize].finest());
            let grant = self.grant(r.tile, wanted);
            match grant.level {
                None => plan.stats.tiles_missing += 1,
                Some(l) => {
                    if let Some(res) = self.resident[r.tile as usize].as_mut() {
                        self.chunks[res.chunk].drawn = Some(frame);
                        if res.speculative.is_some_and(|s| l >= s.from) {
                            res.speculative = None;
                            plan.stats.prefetch_hits += 1;
                        }
                    }
                    if l < wanted {
                        plan.stats.tiles_coarser += 1;
                    }
                }
            }
            if grant.level == Some(wanted) && !touched[k] {
                plan.stats.hits += 1;
            } else {
                plan.stats.misses += 1;
            }
            plan.stats.uploads_deferred_bytes += self.missing_bytes(r.tile, wanted);
            plan.grants.push(grant);
        }
        self.summarise(&mut plan);
        plan
    }

    /// Speculative uploads after this frame's [`plan_frame`](Self::plan_frame) (paper,
    /// section 6): `candidates` are tiles predicted to become visible, soonest first, each with
    /// the level it is predicted to want. Runs only while at least
    /// [`Config::prefetch_free`] of the chunks are free and the frame's upload budget has
    /// room, and stops at either limit. It never evicts (chunks come from the free lists) and
    /// never changes what this frame draws: a tile drawn this frame gets only blocks beyond
    /// its resident ones, within its chunk (nothing it draws reads them); other tiles get a
    /// chunk and the finest level up to the predicted one that the budget allows. Progressive
    /// scheme only.
    pub fn prefetch(&mut self, plan: &mut FramePlan, candidates: &[Request]) {
        self.prefetch_while(plan, candidates, || true);
    }

    /// [`Manager::prefetch`] that also stops before a candidate when `keep_going` says so (the
    /// renderer's CPU budget for prefetching, `vkterrain --prefetch-ms`, is a deadline).
    pub fn prefetch_while(
        &mut self,
        plan: &mut FramePlan,
        candidates: &[Request],
        mut keep_going: impl FnMut() -> bool,
    ) {
        if self.config.scheme != Scheme::Progressive || candidates.is_empty() {
            return;
        }
        let min_free = (self.config.prefetch_free * self.chunks.len() as f64).ceil() as usize;
        let spent: u64 = plan.uploads.iter().map(Upload::sent).sum();
        let mut left = self.config.upload_budget.saturating_sub(spent);
        let requested: std::collections::HashSet<TileId> =
            plan.grants.iter().map(|g| g.tile).collect();
        // Tiles given a spare index array by this call: a later horizon wanting a finer level
        // gets its blocks but does not replace the spare the sooner horizon needs.
        let mut spared = std::collections::HashSet::new();
        self.speculating = true;
        for r in candidates {
            let free = self.chunks.len() - self.owned;
            if left == 0 || free < min_free.max(1) || !keep_going() {
                break;
            }
            let Some(cost) = self.tiles.get(r.tile as usize) else {
                continue;
            };
            let wanted = r.wanted.min(cost.finest());
            let before = plan.uploads.len();
            if requested.contains(&r.tile) {
                let spare = !spared.contains(&r.tile);
                if self.prefetch_blocks(r.tile, wanted, left, free > min_free, spare, plan) {
                    spared.insert(r.tile);
                }
            } else {
                // Taking a chunk needs one free beyond the reserve.
                self.prefetch_level(r.tile, wanted, left, free > min_free, plan);
            }
            let sent = bytes_since(plan, before);
            left = left.saturating_sub(sent);
            plan.stats.prefetch_bytes += sent;
        }
        self.speculating = false;
        self.summarise(plan);
    }

    /// Blocks beyond those resident, up to `wanted`, for a tile drawn this frame, then the
    /// index array of the finest level they complete as a spare beside the drawn one (which
    /// stays). A chunk too small for `wanted`, or without room for the spare, is traded for a
    /// larger one when `may_take_chunk`: the blocks and the drawn index array follow by in-pool
    /// copies, and this frame still draws from the old chunk, which is not reused before it
    /// completes. Without `may_spare` no spare is sent (nor a chunk taken for one). Returns
    /// whether a spare was sent.
    fn prefetch_blocks(
        &mut self,
        tile: TileId,
        wanted: u32,
        left: u64,
        may_take_chunk: bool,
        may_spare: bool,
        plan: &mut FramePlan,
    ) -> bool {
        let Some(mut res) = self.resident[tile as usize] else {
            return false;
        };
        let (Some(b), Some(index), false) = (res.blocks, res.index, res.whole) else {
            return false;
        };
        // Not twice in a frame, and not a chunk with a staged upload this frame (copies run
        // before staged uploads: the move would carry the old index array).
        let moved = self.chunks[res.chunk].copied_in == Some(self.frame)
            || plan
                .uploads
                .iter()
                .any(|u| u.tile == tile && u.gpu_ordered());
        let spare_bytes = self.tiles[tile as usize].levels[wanted as usize].indices;
        let outgrown = wanted > res.layout.capacity && b < wanted;
        // A spare between the drawn level and the one wanted stays: it is the next step, and
        // replacing it by a finer one would leave that step to the frame that needs it.
        let ahead =
            |res: &Resident, level: u32| res.spare.is_some_and(|(s, _)| s > index && s <= level);
        let no_room = may_spare
            && wanted > index
            && !ahead(&res, wanted)
            && self.spare_slot(tile, &res, spare_bytes).is_none();
        if (outgrown || no_room) && may_take_chunk && !moved {
            self.move_with_index(tile, &mut res, b, index, wanted, plan);
        }
        let t = &self.tiles[tile as usize];
        let mut sum = 0;
        let mut top = b;
        for j in b + 1..=wanted.min(res.layout.capacity) {
            if sum + t.block_sent(j) > left {
                break;
            }
            sum += t.block_sent(j);
            top = j;
        }
        for j in b + 1..=top {
            self.push_block(tile, j, (res.chunk, &res.layout), plan);
        }
        let base = self.chunks[res.chunk].offset;
        let t = &self.tiles[tile as usize];
        if top > b {
            res.blocks = Some(top);
            speculate(&mut res, b + 1, sum);
        }
        // The spare: the finest level whose blocks are all there now.
        let level = top.min(wanted);
        let bytes = t.levels[level as usize].indices;
        let mut sent = false;
        let cost = self.index_cost(tile, level);
        if may_spare && level > index && !ahead(&res, level) && sum + cost <= left {
            if let Some(at) = self.spare_slot(tile, &res, bytes) {
                sent = true;
                self.drop_spare(tile, &mut res, plan);
                plan.uploads
                    .push(self.index_upload(tile, level, base + at, res.chunk));
                res.spare = Some((level, at));
            }
        }
        self.resident[tile as usize] = Some(res);
        sent
    }

    /// Moves a drawn tile (blocks `0..=b`, index array of `index`) into a free chunk sized for
    /// `level`, by in-pool copies.
    fn move_with_index(
        &mut self,
        tile: TileId,
        res: &mut Resident,
        b: u32,
        index: u32,
        level: u32,
        plan: &mut FramePlan,
    ) {
        let t = &self.tiles[tile as usize];
        // Room for the drawn array at the index region's start and `level`'s at the end.
        let need = self.tiles.needs(tile as usize)[level as usize];
        let room = t.layout(level).index
            + align(t.levels[index as usize].indices, 4)
            + t.levels[level as usize].indices;
        let Some(chunk) = self
            .obtain(room.max(need), plan)
            .or_else(|| self.obtain(need, plan))
        else {
            return;
        };
        let t = &self.tiles[tile as usize];
        let size = self.classes.sizes[self.chunks[chunk].class];
        let layout = t.layout(t.capacity_in(size).unwrap_or(level).max(level));
        let (old, new) = (self.chunks[res.chunk].offset, self.chunks[chunk].offset);
        for (src, dst, bytes) in [
            (old, new, t.positions_before(b + 1)),
            (
                old + res.layout.morph,
                new + layout.morph,
                t.morph_before(b + 1),
            ),
            (
                old + res.index_at,
                new + layout.index,
                t.levels[index as usize].indices,
            ),
        ] {
            if bytes > 0 {
                plan.moves.push(Move {
                    tile,
                    src,
                    dst,
                    bytes,
                });
            }
        }
        plan.stats.chunk_moves += 1;
        self.swap_chunk(tile, res, chunk, layout, plan);
        // The copies run on the GPU with this frame: a later index upload into the new chunk
        // must be ordered after them, as one into a chunk this frame draws.
        self.chunks[chunk].drawn = Some(self.frame);
    }

    /// Hands `tile` from its chunk to `chunk`, filled by this frame's in-pool copies: the old
    /// chunk is read by them on the GPU, so it retires like a drawn one.
    fn swap_chunk(
        &mut self,
        tile: TileId,
        res: &mut Resident,
        chunk: usize,
        layout: Layout,
        plan: &mut FramePlan,
    ) {
        let old_chunk = res.chunk;
        self.drop_spare(tile, res, plan);
        res.index_at = layout.index;
        self.own(chunk, tile);
        self.chunks[chunk].copied_in = Some(self.frame);
        // The old chunk is read by this frame's copies whether or not the frame draws the tile
        // (a prefetch moves tiles no frame draws): it is not reused before the frame completes,
        // or the next frame's CPU writes could land under the copies (own() marks the new one).
        self.chunks[old_chunk].drawn = Some(self.frame);
        self.chunks[old_chunk].last_used = self.frame;
        self.release(old_chunk);
        res.chunk = chunk;
        res.layout = layout;
    }

    /// The finest level up to `wanted` that `left` bytes bring a tile not drawn this frame to.
    fn prefetch_level(
        &mut self,
        tile: TileId,
        wanted: u32,
        left: u64,
        may_take_chunk: bool,
        plan: &mut FramePlan,
    ) {
        let mut res = match self.resident[tile as usize] {
            Some(res) if res.whole || res.index.is_some_and(|i| i >= wanted) => return,
            Some(res) => res,
            None => {
                if !may_take_chunk {
                    return;
                }
                let t = &self.tiles[tile as usize];
                if t.block_sent(0) + self.index_cost(tile, 0) > left {
                    return;
                }
                let Some(res) = self.admit(tile, wanted, plan) else {
                    return;
                };
                self.resident[tile as usize] = Some(res);
                res
            }
        };
        let from = res.index.map_or(0, |i| i + 1);
        let Some(mut target) = (from..=wanted)
            .rev()
            .find(|&g| self.step_cost(tile, &res, g) <= left)
        else {
            if res.index.is_none() {
                // Admitted, but not even level 0 fits: give the chunk back.
                self.release(res.chunk);
                self.resident[tile as usize] = None;
            }
            return;
        };
        if target > res.layout.capacity {
            let moved = may_take_chunk
                && self.chunks[res.chunk].copied_in != Some(self.frame)
                && self
                    .relocate(tile, &mut res, wanted, target, plan)
                    .is_some();
            if !moved {
                target = res.layout.capacity;
            }
        }
        if res.index.is_some_and(|i| target <= i) {
            self.resident[tile as usize] = Some(res);
            return;
        }
        let before = plan.uploads.len();
        self.resident[tile as usize] = Some(res);
        self.upload_to(tile, target, plan);
        let sent = bytes_since(plan, before);
        if let Some(res) = self.resident[tile as usize].as_mut() {
            speculate(res, from, sent);
        }
    }

    /// The frame's totals from its uploads, moves and the pool's state.
    fn summarise(&self, plan: &mut FramePlan) {
        let s = &mut plan.stats;
        (s.upload_bytes_blocks, s.upload_bytes_indices) = (0, 0);
        for u in plan.uploads.iter().filter(|u| !u.built) {
            match u.part {
                Part::Indices(_) => s.upload_bytes_indices += u.bytes,
                _ => s.upload_bytes_blocks += u.sent(),
            }
        }
        let builds = gpu_builds(&plan.uploads);
        s.index_builds = builds.len() as u64;
        s.index_build_bytes = builds.iter().map(|u| u.bytes).sum();
        s.chunk_move_bytes = plan.moves.iter().map(|m| m.bytes).sum();
        s.chunks_free = (self.chunks.len() - self.owned) as u64;
        (s.resident_bytes, s.used_bytes) = (0, 0);
        // Over the pool's chunks, not the set's tiles: each resident tile owns one chunk
        // ([`Manager::check`]), and a frame's cost follows the pool, not the set's size.
        for (i, c) in self.chunks.iter().enumerate() {
            let Some(t) = c.owner else { continue };
            if let Some(res) = self.resident[t as usize].as_ref().filter(|r| r.chunk == i) {
                s.resident_bytes += self.classes.sizes[c.class];
                s.used_bytes += self.held_bytes(t as usize, res);
            }
        }
    }

    /// Checks the bookkeeping: every resident tile owns exactly its chunk, each chunk has at
    /// most one owner, layouts fit their chunks, the drawn index level's blocks are held, and
    /// the LRU lists hold exactly the owned chunks.
    pub fn check(&self) -> Result<(), String> {
        let mut owners = vec![None; self.chunks.len()];
        for (t, res) in self.resident.iter().enumerate() {
            let Some(res) = res else { continue };
            let c = &self.chunks[res.chunk];
            if c.owner != Some(t as TileId) {
                return Err(format!(
                    "tile {t} holds chunk {} owned by {:?}",
                    res.chunk, c.owner
                ));
            }
            if let Some(other) = owners[res.chunk].replace(t) {
                return Err(format!("chunk {} held by tiles {other} and {t}", res.chunk));
            }
            if res.layout.bytes > self.classes.sizes[c.class] {
                return Err(format!("tile {t}: layout larger than its chunk"));
            }
            if let (Some(i), b) = (res.index, res.blocks) {
                if b.is_none_or(|b| b < i) || i > res.layout.capacity {
                    return Err(format!("tile {t}: index level {i} without its blocks"));
                }
            }
            // Index arrays: inside the index region, 4-aligned, the spare apart from the drawn.
            let size = self.classes.sizes[c.class];
            let cost = &self.tiles[t];
            let array = |level: u32, at: u64| (at, at + cost.levels[level as usize].indices);
            let drawn = res.index.map(|i| array(i, res.index_at));
            let spare = res.spare.map(|(s, at)| array(s, at));
            for (start, end) in drawn.iter().chain(&spare) {
                if *start < res.layout.index || *end > size || start % 4 != 0 {
                    return Err(format!(
                        "tile {t}: index array at {start}..{end} out of place"
                    ));
                }
            }
            if let (Some(d), Some(s)) = (drawn, spare) {
                if d.0 < s.1 && s.0 < d.1 {
                    return Err(format!("tile {t}: spare index array over the drawn one"));
                }
            }
            if let Some((s, _)) = res.spare {
                if res.blocks.is_none_or(|b| b < s) || s > res.layout.capacity {
                    return Err(format!(
                        "tile {t}: spare index level {s} without its blocks"
                    ));
                }
            }
        }
        let owned = self.chunks.iter().filter(|c| c.owner.is_some()).count();
        if owned != self.owned {
            return Err(format!("{owned} chunks owned, counted {}", self.owned));
        }
        for (i, c) in self.chunks.iter().enumerate() {
            if c.owner.is_some() != owners[i].is_some() {
                return Err(format!("chunk {i} owned by {:?} but not held", c.owner));
            }
            let listed = self.lru.list_of(i);
            if (c.owner.is_some() && listed != Some(c.class))
                || (c.owner.is_none() && listed.is_some())
            {
                return Err(format!("chunk {i}: LRU list out of step"));
            }
        }
        for class in 0..self.classes.sizes.len() {
            let used: Vec<u64> = self
                .lru
                .iter(class)
                .map(|c| self.chunks[c].last_used)
                .collect();
            if used.windows(2).any(|w| w[0] > w[1]) {
                return Err(format!("class {class}: LRU list not in order of last use"));
            }
        }
        let resident: u64 = self
            .resident
            .iter()
            .flatten()
            .map(|r| self.classes.sizes[self.chunks[r.chunk].class])
            .sum();
        if resident > self.pool_bytes() {
            return Err(format!(
                "{resident} bytes resident in a pool of {}",
                self.pool_bytes()
            ));
        }
        Ok(())
    }

    /// Bytes of tile data a resident tile holds.
    fn held_bytes(&self, tile: usize, res: &Resident) -> u64 {
        let t = &self.tiles[tile];
        if res.whole {
            return t.whole();
        }
        let blocks: u64 = res
            .blocks
            .map_or(0, |b| (0..=b).map(|j| t.block_bytes(j)).sum());
        blocks
            + res.index.map_or(0, |i| t.levels[i as usize].indices)
            + self.spare_bytes(tile as TileId, res)
    }

    /// Bytes of `res`'s spare index array (0 without one).
    fn spare_bytes(&self, tile: TileId, res: &Resident) -> u64 {
        res.spare.map_or(0, |(s, _)| {
            self.tiles[tile as usize].levels[s as usize].indices
        })
    }

    /// Bytes sent for `res`'s spare index array (0 without one, or when it was built).
    fn spare_sent(&self, tile: TileId, res: &Resident) -> u64 {
        res.spare.map_or(0, |(s, _)| self.index_cost(tile, s))
    }

    /// Drops `res`'s spare index array, unused: the bytes sent for it were wasted.
    fn drop_spare(&self, tile: TileId, res: &mut Resident, plan: &mut FramePlan) {
        plan.stats.prefetch_wasted_bytes += self.spare_sent(tile, res);
        res.spare = None;
    }

    /// Upload-budget bytes of level `level`'s index array: its size when sent, nothing when
    /// built on the GPU.
    fn index_cost(&self, tile: TileId, level: u32) -> u64 {
        match self.config.index_arrays {
            IndexArrays::Sent => self.tiles[tile as usize].levels[level as usize].indices,
            IndexArrays::Built => 0,
        }
    }

    /// The upload of level `level`'s index array to pool offset `dst` in `chunk`.
    fn index_upload(&mut self, tile: TileId, level: u32, dst: u64, chunk: usize) -> Upload {
        let built = self.config.index_arrays == IndexArrays::Built;
        if built {
            self.written_on_gpu(chunk);
        }
        Upload {
            tile,
            part: Part::Indices(level),
            dst,
            bytes: self.tiles[tile as usize].levels[level as usize].indices,
            in_flight: self.read_in_flight(chunk),
            chunk: self.chunks[chunk].offset,
            built,
            stream: None,
        }
    }

    /// Where in `res`'s chunk an index array of `bytes` can go without touching the drawn one
    /// (nor the blocks): the chunk's end if there is room after the drawn array, else the
    /// index region's start if there is room before it. Ping-pong between the two ends lets
    /// a region as large as two consecutive arrays hold both.
    fn spare_slot(&self, tile: TileId, res: &Resident, bytes: u64) -> Option<u64> {
        let index = res.index?;
        let end = self.classes.sizes[self.chunks[res.chunk].class];
        let drawn = (
            res.index_at,
            res.index_at + self.tiles[tile as usize].levels[index as usize].indices,
        );
        let at_end = end.checked_sub(bytes)? / 4 * 4;
        if at_end >= drawn.1 && at_end >= res.layout.index {
            Some(at_end)
        } else if res.layout.index + bytes <= drawn.0 {
            Some(res.layout.index)
        } else {
            None
        }
    }

    /// Bytes `tile` still lacks to be drawn at `wanted`.
    fn missing_bytes(&self, tile: TileId, wanted: u32) -> u64 {
        let t = &self.tiles[tile as usize];
        match self.resident[tile as usize] {
            Some(res) if res.whole => 0,
            Some(res) => self.step_cost(tile, &res, wanted),
            None => {
                (0..=wanted).map(|j| t.block_sent(j)).sum::<u64>() + self.index_cost(tile, wanted)
            }
        }
    }

    fn grant(&self, tile: TileId, wanted: u32) -> Grant {
        let none = Grant {
            tile,
            wanted,
            level: None,
            vertex_offset: 0,
            morph_offset: 0,
            index_offset: 0,
            index_width: 0,
        };
        let Some(res) = self.resident[tile as usize] else {
            return none;
        };
        let level = if res.whole { Some(wanted) } else { res.index };
        let Some(level) = level else { return none };
        let chunk = &self.chunks[res.chunk];
        let t = &self.tiles[tile as usize];
        // A whole tile holds every index array, one after another.
        let index_before = if res.whole {
            t.whole_index_before(level)
        } else {
            0
        };
        Grant {
            tile,
            wanted,
            level: Some(level),
            vertex_offset: chunk.offset,
            morph_offset: chunk.offset + res.layout.morph,
            index_offset: chunk.offset + res.index_at + index_before,
            index_width: self.tiles[tile as usize].levels[level as usize].index_width,
        }
    }

    /// Bytes to go from what `res` holds to drawing `level`.
    fn step_cost(&self, tile: TileId, res: &Resident, level: u32) -> u64 {
        let t = &self.tiles[tile as usize];
        if res.index == Some(level) {
            return 0;
        }
        let first_block = match (self.config.scheme, res.blocks) {
            (Scheme::Progressive, Some(b)) => b + 1,
            _ => 0,
        };
        let blocks: u64 = (first_block..=level).map(|j| t.block_sent(j)).sum();
        let index = match res.spare {
            Some((s, _)) if s == level => 0,
            _ => self.index_cost(tile, level),
        };
        blocks + index
    }

    fn refine(&mut self, r: Request, spent: u64, plan: &mut FramePlan) {
        let Some(mut res) = self.resident[r.tile as usize] else {
            return;
        };
        if res.whole {
            return;
        }
        let finest = self.tiles[r.tile as usize].finest();
        let wanted = r.wanted.min(finest);
        let Some(current) = res.index else { return };
        if current == wanted
            || (wanted < current && current - wanted <= self.config.downgrade_slack)
        {
            return;
        }
        let left = self.config.upload_budget.saturating_sub(spent);
        // Levels to consider, best first: the wanted one, then (refining) the ones between.
        let candidates: Vec<u32> = if wanted < current {
            vec![wanted]
        } else {
            (current + 1..=wanted).rev().collect()
        };
        let fits = |m: &Self, res: &Resident, g: u32| m.step_cost(r.tile, res, g) <= left;
        let mut target = candidates.iter().copied().find(|&g| fits(self, &res, g));
        if target.is_none() && spent == 0 && wanted > current {
            // The budget is smaller than one step: take the smallest, alone this frame.
            target = Some(current + 1);
        }
        let Some(mut target) = target else { return };
        if target > res.layout.capacity {
            // Outgrown: move to the tightest chunk for the wanted level (or at least this one).
            let moved = self
                .relocate(r.tile, &mut res, wanted, target, plan)
                .or_else(|| self.relocate(r.tile, &mut res, target, target, plan));
            if moved.is_none() {
                target = res.layout.capacity;
                if target == current || !fits(self, &res, target) {
                    return;
                }
            }
        }
        self.resident[r.tile as usize] = Some(res);
        self.upload_to(r.tile, target, plan);
    }

    /// Moves `tile` into a chunk holding levels up to `level` (at least `min`); records the copy.
    fn relocate(
        &mut self,
        tile: TileId,
        res: &mut Resident,
        level: u32,
        min: u32,
        plan: &mut FramePlan,
    ) -> Option<()> {
        // Not a tile whose blocks this frame decodes on the GPU: the decodes run after the
        // frame's copies, so the move would carry the blocks' old bytes.
        if plan
            .uploads
            .iter()
            .any(|u| u.tile == tile && u.stream.is_some())
        {
            return None;
        }
        let bytes = self.tiles.needs(tile as usize)[level as usize];
        let chunk = self.obtain(bytes, plan)?;
        let t = &self.tiles[tile as usize];
        let size = self.classes.sizes[self.chunks[chunk].class];
        // obtain() gives at least `bytes`, so the chunk holds `level >= min`.
        let layout = t.layout(t.capacity_in(size).unwrap_or(level).max(min));
        let (old, new) = (self.chunks[res.chunk].offset, self.chunks[chunk].offset);
        if let Some(b) = res.blocks {
            let positions = t.positions_before(b + 1);
            let morph = t.morph_before(b + 1);
            plan.moves.push(Move {
                tile,
                src: old,
                dst: new,
                bytes: positions,
            });
            if morph > 0 {
                plan.moves.push(Move {
                    tile,
                    src: old + res.layout.morph,
                    dst: new + layout.morph,
                    bytes: morph,
                });
            }
        }
        plan.stats.chunk_moves += 1;
        self.swap_chunk(tile, res, chunk, layout, plan);
        // The index array is not moved: the refinement that caused the move replaces it.
        res.index = None;
        Some(())
    }

    /// A chunk for a new tile: the tightest class for its wanted level, else any that holds
    /// level 0.
    fn admit(&mut self, tile: TileId, wanted: u32, plan: &mut FramePlan) -> Option<Resident> {
        let needs = self.tiles.needs(tile as usize);
        let (want, least) = (needs[wanted as usize], needs[0]);
        let chunk = self
            .obtain(want, plan)
            .or_else(|| self.obtain(least, plan))?;
        self.own(chunk, tile);
        let t = &self.tiles[tile as usize];
        let size = self.classes.sizes[self.chunks[chunk].class];
        let layout = match self.config.scheme {
            Scheme::WholeTile => t.whole_layout(),
            _ => t.layout(t.capacity_in(size).unwrap_or(0)),
        };
        Some(Resident {
            chunk,
            layout,
            blocks: None,
            index: None,
            index_at: layout.index,
            spare: None,
            whole: false,
            speculative: None,
        })
    }

    /// Records the uploads that let `tile` draw `level` (its chunk holds it).
    fn upload_to(&mut self, tile: TileId, level: u32, plan: &mut FramePlan) {
        let Some(mut res) = self.resident[tile as usize] else {
            return;
        };
        let first_block = match (self.config.scheme, res.blocks) {
            (Scheme::Progressive, Some(b)) => b + 1,
            _ => 0,
        };
        for j in first_block..=level {
            self.push_block(tile, j, (res.chunk, &res.layout), plan);
        }
        let base = self.chunks[res.chunk].offset;
        let t = &self.tiles[tile as usize];
        let bytes = t.levels[level as usize].indices;
        if let Some((_, at)) = res.spare.filter(|&(s, _)| s == level) {
            // Sent ahead by a prefetch: draw it (a hit when a frame does, not another prefetch).
            res.index_at = at;
            res.spare = None;
            if !self.speculating {
                plan.stats.prefetch_hits += 1;
            }
        } else {
            if res.index.is_some_and(|previous| level < previous) {
                plan.stats.upload_bytes_coarser += self.index_cost(tile, level);
            }
            plan.uploads
                .push(self.index_upload(tile, level, base + res.layout.index, res.chunk));
            res.index_at = res.layout.index;
            if res
                .spare
                .is_some_and(|(_, at)| at < res.layout.index + bytes)
            {
                self.drop_spare(tile, &mut res, plan);
            }
        }
        res.blocks = Some(res.blocks.map_or(level, |b| b.max(level)));
        if self.config.scheme == Scheme::PerLevel {
            res.blocks = Some(level);
        }
        res.index = Some(level);
        self.resident[tile as usize] = Some(res);
    }

    /// Whether a frame not known to have completed drew from `chunk` (a write there must be
    /// ordered after it on the GPU).
    fn read_in_flight(&self, chunk: usize) -> bool {
        self.chunks[chunk]
            .drawn
            .is_some_and(|d| self.completed.is_none_or(|c| d > c))
    }

    /// Records the upload of block `j`'s positions and morph rows into the chunk at `base`.
    fn push_block(
        &mut self,
        tile: TileId,
        j: u32,
        (chunk, layout): (usize, &Layout),
        plan: &mut FramePlan,
    ) {
        let base = self.chunks[chunk].offset;
        if self.tiles[tile as usize].levels[j as usize]
            .stream
            .is_some()
        {
            self.written_on_gpu(chunk);
        }
        let t = &self.tiles[tile as usize];
        let l = &t.levels[j as usize];
        plan.uploads.push(Upload {
            tile,
            part: Part::Positions(j),
            dst: base + t.positions_before(j),
            bytes: l.positions,
            in_flight: false,
            chunk: base,
            built: false,
            stream: l.stream,
        });
        if l.morph > 0 {
            plan.uploads.push(Upload {
                tile,
                part: Part::Morph(j),
                dst: base + layout.morph + t.morph_before(j),
                bytes: l.morph,
                in_flight: false,
                chunk: base,
                built: false,
                stream: None,
            });
        }
    }

    fn upload_whole(&mut self, tile: TileId, plan: &mut FramePlan) {
        let Some(mut res) = self.resident[tile as usize] else {
            return;
        };
        let t = &self.tiles[tile as usize];
        let base = self.chunks[res.chunk].offset;
        let layout = res.layout;
        for (j, l) in t.levels.iter().enumerate() {
            let j = j as u32;
            for (part, bytes, dst) in [
                (Part::Positions(j), l.positions, t.positions_before(j)),
                (Part::Morph(j), l.morph, layout.morph + t.morph_before(j)),
                (
                    Part::Indices(j),
                    l.indices,
                    layout.index + t.whole_index_before(j),
                ),
            ] {
                if bytes > 0 {
                    plan.uploads.push(Upload {
                        tile,
                        part,
                        dst: base + dst,
                        bytes,
                        in_flight: false,
                        chunk: base,
                        built: false,
                        stream: None,
                    });
                }
            }
        }
        res.blocks = Some(t.finest());
        res.index = Some(t.finest());
        res.whole = true;
        self.resident[tile as usize] = Some(res);
    }

    /// Frees chunks whose last reader has completed.
    fn retire(&mut self) {
        let completed = self.completed;
        let chunks = &self.chunks;
        let mut ready = Vec::new();
        self.retiring.retain(|&c| {
            let done = completed.is_some_and(|f| chunks[c].last_used <= f);
            if done {
                ready.push(c);
            }
            !done
        });
        for c in ready {
            self.free[self.chunks[c].class].push(c);
        }
    }

    /// A chunk last used in frame `used` may be evicted: it is not requested this frame, and
    /// every frame that may read it has completed.
    fn evictable(&self, used: u64) -> bool {
        used < self.frame && self.completed.is_some_and(|f| used <= f)
    }

    /// This frame's commands write `chunk` on the GPU (an index array built, a block decoded)
    /// and read the tile's blocks there: it is used by this frame, so it is not evicted or
    /// reused before the frame completes (a prefetch writes into chunks no frame draws).
    fn written_on_gpu(&mut self, chunk: usize) {
        self.touch(chunk);
        self.chunks[chunk].gpu_written_in = Some(self.frame);
    }

    fn touch(&mut self, chunk: usize) {
        let c = self.chunks[chunk];
        if c.owner.is_some() {
            self.lru.touch(c.class, chunk);
        }
        self.chunks[chunk].last_used = self.frame;
    }

    fn own(&mut self, chunk: usize, tile: TileId) {
        let c = &mut self.chunks[chunk];
        c.owner = Some(tile);
        c.last_used = self.frame;
        c.drawn = None;
        self.lru.push_back(c.class, chunk);
        self.owned += 1;
    }

    /// Gives a chunk up; it is reused once every frame that may read it has completed.
    fn release(&mut self, chunk: usize) {
        let c = self.chunks[chunk];
        self.lru.remove(chunk);
        if self.chunks[chunk].owner.take().is_some() {
            self.owned -= 1;
        }
        let gpu_writes = c.copied_in == Some(self.frame) || c.gpu_written_in == Some(self.frame);
        if c.drawn.is_none() && c.last_used == self.frame && !gpu_writes {
            // Never drawn (taken this frame and given back), and nothing this frame's commands
            // write goes there: nobody reads it, and whoever takes it next may write it now.
            self.free[c.class].push(chunk);
        } else {
            self.retiring.push(chunk);
        }
    }

    /// At least the bytes a new tile's presence sends: its level 0 (every level under the
    /// whole-tile scheme), positions or streams, morph rows and index arrays.
    fn presence_bound(&self, tile: TileId) -> u64 {
        let t = &self.tiles[tile as usize];
        let levels = match self.config.scheme {
            Scheme::WholeTile => t.finest() + 1,
            _ => 1,
        };
        (0..levels)
            .map(|j| t.block_sent(j).max(t.block_bytes(j)) + t.levels[j as usize].indices)
            .sum()
    }

    /// A chunk of at least `bytes`: the tightest free class, else a victim.
    fn obtain(&mut self, bytes: u64, plan: &mut FramePlan) -> Option<usize> {
        let first = self.classes.class_for(bytes)?;
        for class in first..self.classes.sizes.len() {
            if let Some(c) = self.free[class].pop() {
                return Some(c);
            }
        }
        if self.speculating {
            return None;
        }
        let victim = self.victim(first, bytes)?;
        if let Some(owner) = self.chunks[victim].owner {
            if let Some(res) = self.resident[owner as usize] {
                plan.stats.prefetch_wasted_bytes +=
                    res.speculative.map_or(0, |s| s.bytes) + self.spare_sent(owner, &res);
            }
            self.resident[owner as usize] = None;
        }
        self.lru.remove(victim);
        if self.chunks[victim].owner.take().is_some() {
            self.owned -= 1;
        }
        plan.stats.evictions += 1;
        Some(victim)
    }

    fn victim(&self, first: usize, bytes: u64) -> Option<usize> {
        // The oldest evictable chunk of a class: LRU order. Whether a chunk is evictable
        // depends only on its last use (not this frame, and no frame in flight), so the
        // evictable chunks are a prefix of the order: the oldest is the first, or none is.
        let evictable = |used: u64| self.evictable(used);
        let oldest = |class: usize| {
            self.lru
                .oldest(class)
                .map(|c| (self.chunks[c].last_used, c))
                .filter(|&(used, _)| evictable(used))
        };
        let classes = first..self.classes.sizes.len();
        match self.config.victim {
            Victim::Lru => classes.filter_map(oldest).min().map(|(_, c)| c),
            Victim::TightestFit => classes.filter_map(oldest).next().map(|(_, c)| c),
            Victim::Mixture => {
                let score = |(used, c): (u64, usize)| {
                    let age = (self.frame - used) as f64;
                    let waste = (self.classes.sizes[self.chunks[c].class] as f64
                        / bytes.max(1) as f64)
                        .log2();
                    (1.0 + age).ln() - self.config.weight * waste
                };
                classes
                    .filter_map(oldest)
                    .max_by(|&a, &b| score(a).total_cmp(&score(b)).then(b.1.cmp(&a.1)))
                    .map(|(_, c)| c)
            }
            Victim::Belady => {
                let next = self.oracle.as_ref();
                classes
                    .flat_map(|class| {
                        self.lru
                            .iter(class)
                            .take_while(|&c| evictable(self.chunks[c].last_used))
                    })
                    .max_by_key(|&c| {
                        let owner = self.chunks[c].owner.unwrap_or(0);
                        let n = next.map_or(0, |f| f(owner, self.frame));
                        // Farthest next use; among equals, the smallest chunk.
                        (n, std::cmp::Reverse(self.chunks[c].class), c)
                    })
            }
        }
    }
}

/// Marks `bytes` more of `res` as prefetched, from block `from` on.
fn speculate(res: &mut Resident, from: u32, bytes: u64) {
    let s = res
        .speculative
        .get_or_insert(Speculation { from, bytes: 0 });
    s.from = s.from.min(from);
    s.bytes += bytes;
}

/// Bytes of the uploads planned after the first `before`.
fn bytes_since(plan: &FramePlan, before: usize) -> u64 {
    plan.uploads[before..].iter().map(Upload::sent).sum()
}
