//! A mapped tile set as the renderer sees it. Opening reads the header and the directory (both
//! checksummed), whatever the number of tiles; each tile's header and level table (its world
//! box, level tables and memory costs, for culling, LOD and the memory manager) is read the
//! first time the tile is asked for ([`crate::store`]), while its data stay on disk. A tile is
//! checked the first time it is needed
//! ([`Terrain::check_through`]): its checksum, structure and `tiletool verify`'s semantic checks
//! of the levels wanted, and of each finer level when first wanted, before any of their bytes
//! reach the GPU. A tile that fails is never drawn; the flight goes on without it and
//! [`Terrain::take_failures`] names it.

use std::collections::{HashMap, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::Duration;

use glam::DVec3;
use tiles::format::{LevelEntry, TileSet};
use tiles::mesh::{TILE_CELLS, TILE_SIZE};

pub use crate::store::Layer;
use crate::store::Tiles;
use crate::tile::{rebase, Paged, Side, Sides, TileInfo, HEIGHT_CELLS};

pub struct Terrain {
    /// The base grid's view of the file.
    pub set: TileSet,
    /// The base grid's tiles (row-major), then, when opened with its pyramid
    /// ([`Terrain::open_pyramid`]), each layer's above it ([`Terrain::layers`]); each read
    /// when first asked for.
    pub tiles: Arc<Tiles>,
    /// The base grid's tiles per row and column.
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Layer 0 (the base grid) and the pyramid layers opened above it: where each layer's
    /// tiles start in `tiles`, its grid of tiles and its view of the file.
    pub layers: Vec<Layer>,
    pub levels: u32,
    pub spacing: (f64, f64),
    pub height_step: f32,
    /// Neighbouring tiles have the same side vertices at every level, with the same morph
    /// offsets ([`tiles::format::FLAG_SHARED_SIDES`], checked against the borders here):
    /// geomorphing gives a shared side vertex the same height from both tiles, so stitches
    /// need no slivers between two copies of it. A caller may set it to stitch without
    /// slivers anyway (`--no-slivers`, to show the cracks); the checks follow the file's claim.
    pub shared_sides: bool,
    /// What the file's header claims: the side checks hold tiles to it.
    sides_claimed: bool,
    /// The texture tiles' layout (None: the set has none) and what they show
    /// (`tiles::texture::SOURCE_*`).
    pub texture: Option<tiles::texture::Layout>,
    pub texture_source: u32,
    /// Tiles that failed their check, in the order they failed, not yet taken.
    failures: Mutex<Vec<usize>>,
    failed: AtomicUsize,
    /// Tiles to check ahead of need, soonest first, each through a level
    /// ([`Terrain::check_soon`]), and the signal that wakes the thread checking them.
    ahead: Mutex<VecDeque<(usize, u32)>>,
    ahead_ready: Condvar,
    /// Held (shared) by each check while it reads tile data, and alone by
    /// [`Terrain::with_checks_held`].
    reading: RwLock<()>,
    /// Pyramid layers' coarse height maps read so far, by layer, column and row
    /// ([`Terrain::max_height_near`]; the base grid's are its tiles').
    layer_heights: Mutex<HashMap<(u32, u32, u32), [f32; HEIGHT_CELLS * HEIGHT_CELLS]>>,
}

impl Terrain {
    /// Opens the tile set: the header and directory with their checksum. Each tile's header
    /// and level table (its outline, a page of the file) is read the first time the tile is
    /// asked for ([`Tiles`]), and its data are checked when first needed
    /// ([`Terrain::check`]): the open costs the same whatever the set's size.
    pub fn open(path: &Path) -> Result<Terrain, tiles::FormatError> {
        Terrain::open_layer(path, 0)
    }

    /// [`Terrain::open`] for pyramid layer `layer` of the set (0: the base grid): the layer's
    /// tiles as a terrain of their own, over the same ground at `2^layer` times the spacing.
    pub fn open_layer(path: &Path, layer: u32) -> Result<Terrain, tiles::FormatError> {
        let file = TileSet::open(path)?;
        let set = file
            .layer(layer)
            .ok_or_else(|| tiles::FormatError::Invalid {
                path: path.to_path_buf(),
                what: format!(
                    "no pyramid layer {layer}: the set has {} above its base grid",
                    file.pyramid_layers()
                ),
            })?;
        Ok(Terrain::of_layers(vec![set]))
    }

    /// [`Terrain::open`] with every pyramid layer of the set above the base grid, their tiles
    /// after the base grid's in one index space (the frame's cut chooses among them,
    /// `renderer::cut`). A set without a pyramid opens as [`Terrain::open`] does.
    pub fn open_pyramid(path: &Path) -> Result<Terrain, tiles::FormatError> {
        let file = TileSet::open(path)?;
        let layers = (0..=file.pyramid_layers()).map_while(|p| file.layer(p));
        Ok(Terrain::of_layers(layers.collect()))
    }

    /// Level tables for a morph rule that reads the stored offsets (`--morph-shader
    /// two-levels` and `forward-differences`): each level's measured error plus half its
    /// morph unit, the offsets' rounding. The default, the morph pass, blends the levels' own
    /// surfaces and takes the measured errors. Called before anything reads a tile.
    pub fn read_stored_offsets(&mut self) {
        Arc::get_mut(&mut self.tiles)
            .expect("the tables' rule is set on a terrain just opened")
            .set_rounding(true);
    }

    /// The terrain of a tile set already open (a layer's view, [`TileSet::layer`], or the
    /// base grid).
    pub fn of_layer(set: TileSet) -> Result<Terrain, tiles::FormatError> {
        Ok(Terrain::of_layers(vec![set]))
    }

    /// The terrain of `sets`: the first as its base grid, each next one the layer above.
    fn of_layers(sets: Vec<TileSet>) -> Terrain {
        let mut first = 0;
        let layers: Vec<Layer> = sets
            .into_iter()
            .map(|set| {
                let h = *set.header();
                let layer = Layer {
                    first,
                    tiles_x: h.tiles_x,
                    tiles_y: h.tiles_y,
                    set,
                };
                first += layer.len();
                layer
            })
            .collect();
        let set = layers[0].set.clone();
        let h = *set.header();
        Terrain {
            tiles: Arc::new(Tiles::new(layers.clone())),
            texture: set.texture_layout(),
            set,
            layers,
            tiles_x: h.tiles_x,
            tiles_y: h.tiles_y,
            levels: h.levels,
            spacing: (h.spacing_x, h.spacing_y),
            height_step: h.height_step,
            // A file that claims shared sides but whose borders differ (tampered with) loses
            // the tiles whose sides differ, when they are checked.
            shared_sides: h.flags & tiles::format::FLAG_SHARED_SIDES != 0,
            sides_claimed: h.flags & tiles::format::FLAG_SHARED_SIDES != 0,
            texture_source: h.texture_source,
            failures: Mutex::new(Vec::new()),
            failed: AtomicUsize::new(0),
            ahead: Mutex::new(VecDeque::new()),
            ahead_ready: Condvar::new(),
            reading: RwLock::new(()),
            layer_heights: Mutex::new(HashMap::new()),
        }
    }

    /// The index of the top layer opened (0: the base grid alone).
    pub fn top(&self) -> u32 {
        self.layers.len() as u32 - 1
    }

    /// The base grid's tiles: the first of [`Terrain::tiles`], each read as the iteration
    /// reaches it (a sweep of the base grid).
    pub fn base(&self) -> impl ExactSizeIterator<Item = &TileInfo> + '_ {
        (0..self.layers[0].len()).map(|i| &self.tiles[i])
    }

    /// Tile `i` of layer `p`'s index in [`Terrain::tiles`].
    pub fn index_in(&self, p: u32, i: usize) -> usize {
        self.layers[p as usize].first + i
    }

    /// The tile at column `tx`, row `ty` of layer `p`, if the layer has one.
    pub fn tile_in(&self, p: u32, tx: u32, ty: u32) -> Option<usize> {
        let l = self.layers.get(p as usize)?;
        (tx < l.tiles_x && ty < l.tiles_y).then(|| l.first + (ty * l.tiles_x + tx) as usize)
    }

    /// The file's view that holds `tile`'s data: its layer's.
    pub fn set_of(&self, tile: &TileInfo) -> &TileSet {
        &self.layers[tile.layer as usize].set
    }

    /// Metres per height code of `tile`'s layer (each layer has its own lattice).
    pub fn height_step_of(&self, tile: &TileInfo) -> f32 {
        self.set_of(tile).header().height_step
    }

    /// Tiles (indices in [`Terrain::tiles`]) of layer `p - 1` under tile `i` (an index in
    /// [`Terrain::tiles`]) of layer `p >= 1`: up to 2 x 2.
    pub fn children(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let t = &self.tiles[i];
        let p = t.layer;
        let (tx, ty) = (t.tx, t.ty);
        (0..4u32)
            .filter(move |_| p >= 1)
            .filter_map(move |k| self.tile_in(p - 1, 2 * tx + k % 2, 2 * ty + k / 2))
    }

    /// The tile of layer `p + 1` over tile `i` (of layer `p`), if the set has that layer.
    pub fn parent(&self, i: usize) -> Option<usize> {
        let t = &self.tiles[i];
        self.tile_in(t.layer + 1, t.tx / 2, t.ty / 2)
    }

    /// The base grid's tiles under tile `i` (an index in [`Terrain::tiles`]): columns and
    /// rows.
    pub fn base_tiles_under(&self, i: usize) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let t = &self.tiles[i];
        let f = 1u32 << t.layer;
        (
            (t.tx * f).min(self.tiles_x)..((t.tx + 1) * f).min(self.tiles_x),
            (t.ty * f).min(self.tiles_y)..((t.ty + 1) * f).min(self.tiles_y),
        )
    }

    /// Checks tile `i` for drawing at every level: [`Terrain::check_through`] its finest.
    pub fn check(&self, i: usize) -> Result<&Paged, &str> {
        self.check_through(i, u32::MAX)
    }

    /// Checks tile `i` for drawing at levels up to `level` (clamped to its finest), before
    /// any of those levels' bytes reach the GPU ([`Terrain::part`] hands out no others).
    ///
    /// The first call makes the tile's own check (later calls return its answer; a call while
    /// another thread makes it waits for it): its checksum, structure and texture, and
    /// `tiletool verify`'s semantic checks without a source (fans, coverage, nesting, blocks,
    /// borders, morph offsets) of levels `0..=level`; and where the set shares sides, that each
    /// side holds the same vertices as the neighbour's at every level read (every level of a
    /// version 3 tile; a compact tile is rebuilt through `level` alone, and each finer level's
    /// sides are compared when it is checked; a neighbour that failed
    /// its own check, or whose data do not read, is never drawn, so no seam joins them and no
    /// side is compared; a neighbour not checked yet gives its sides as stored, read again
    /// with its checksum only where they differ, without the semantic checks: a pyramid's cut
    /// rarely draws a tile's neighbours in its own layer, and checking each whole doubled the
    /// checks' cost over a flight; a compact neighbour's sides are decoded, not rebuilt). A
    /// later call for a finer level checks the levels in between; one that fails then takes the
    /// tile out of the flight from then on. A tile is
    /// mostly first drawn at a coarse level, and its finer levels hold most of its vertices:
    /// the 16K mirror set's first flyover view checks its 96 tiles through the levels it draws
    /// them at in a seventh of the time all nine levels take (bench/README, "A tile's levels
    /// checked as they are first needed"). Checksums catch accidents; the rest catches a file
    /// whose checksums were recomputed over nonsense. Returns the problem, as one line naming
    /// the file and the tile.
    ///
    /// A check that would read the tile's data from a file shorter than it was at open (cut
    /// in place by another process: reading the mapping past its end would fault) reads
    /// nothing and returns that problem, without counting the tile as failed: the frame's
    /// uploads stop the flight on it (`renderer::frame`). A file cut while a check reads it
    /// can still fault; tile sets are meant to be replaced by rename, as tiletool writes them.
    pub fn check_through(&self, i: usize, level: u32) -> Result<&Paged, &str> {
        let tile = self.tiles.get(i).ok_or("no such tile")?;
        let level = level.min((tile.levels.len() as u32).saturating_sub(1));
        let _reading = self.reading.read().unwrap_or_else(|p| p.into_inner());
        let reads = tile.usable.get().is_none()
            || (tile.checked_levels() <= level && tile.late.get().is_none());
        if reads && self.shrank() {
            return Err("the tile set changed on disk while in use");
        }
        let usable = tile.usable.get_or_init(|| {
            let verdict = self.usable(tile, level);
            if verdict.is_err() {
                self.failed_at(i);
            }
            verdict
        });
        let paged = match (usable, self.own(tile, level)) {
            (Ok(()), Ok(paged)) => paged,
            (Err(e), _) | (_, Err(e)) => return Err(e),
        };
        if tile.checked_levels() <= level {
            self.check_finer(i, level);
        }
        match tile.late.get() {
            Some(problem) => Err(problem),
            None => Ok(paged),
        }
    }

    /// Checks tile `i`'s levels from the first not checked yet through `level`, after its own
    /// check passed.
    fn check_finer(&self, i: usize, level: u32) {
        let tile = &self.tiles[i];
        let _held = tile
            .extending
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let from = tile.checked_levels();
        if from > level || tile.late.get().is_some() {
            return;
        }
        // Its checksum passed its own check, over these same bytes (a file cut since is refused
        // before this): the outline (a compact tile rebuilt through `level`), and the new
        // levels' structure.
        let set = self.set_of(tile);
        let problem = match set.tile_outline_through(tile.tx, tile.ty, level + 1) {
            Ok(data) => {
                let problem = match data.check_levels(from..level + 1) {
                    Err(what) => Some(set.tile_error(tile.tx, tile.ty, what).to_string()),
                    Ok(()) => tiles::verify::tile_problems_in(set, &data, from..level + 1)
                        .into_iter()
                        .next(),
                };
                match (problem, tile.paged()) {
                    (None, Some(paged)) => self.extend_paged(tile, paged, &data, level).err(),
                    (problem, _) => problem,
                }
            }
            Err(e) => Some(e.to_string()),
        };
        match problem {
            None => tile.checked.store(level + 1, Ordering::Release),
            Some(what) => {
                let _ = tile.late.set(self.named(what));
                self.failed_at(i);
            }
        }
    }

    /// What a check of `tile`'s levels through `level` adds to what its first check read,
    /// before those levels may be drawn: their part tables, and the sides of a tile whose
    /// first check read fewer levels (a compact tile rebuilt that far), compared with the
    /// neighbours' at those levels.
    fn extend_paged(
        &self,
        tile: &TileInfo,
        paged: &Paged,
        data: &tiles::format::Tile,
        level: u32,
    ) -> Result<(), String> {
        let known = paged.sides().borders.len();
        let held = paged.parts();
        // The tables' centres and lines come from every block the tile held when they were
        // made: made again where it holds more now.
        let tables = match data.levels().len() > known {
            true => tiles::parts::tables_through(data, level + 1),
            false => (
                held.0,
                tiles::parts::counts_through(data, &held.1, level + 1),
            ),
        };
        *paged.parts.write().unwrap_or_else(|p| p.into_inner()) = Arc::new(tables);
        if known > level as usize {
            return Ok(());
        }
        let sides = sides(data).ok_or("a border names a vertex outside its blocks")?;
        self.sides_agree(tile, &sides.borders, known..sides.borders.len())?;
        *paged.sides.write().unwrap_or_else(|p| p.into_inner()) = Arc::new(sides);
        Ok(())
    }

    /// Whether the file on disk is shorter now than when it was opened (its length, as the
    /// frame's uploads check it).
    fn shrank(&self) -> bool {
        std::fs::metadata(self.set.path()).is_ok_and(|m| m.len() < self.set.file_len())
    }

    /// Runs `f` while no check reads tile data (checks wait for it): what changes the file in
    /// place does it here (`VKTERRAIN_FAULT=truncate-at-N`).
    pub fn with_checks_held<R>(&self, f: impl FnOnce() -> R) -> R {
        let _held = self.reading.write().unwrap_or_else(|p| p.into_inner());
        f()
    }

    /// Counts tile `i` as failed and lists it for [`Terrain::take_failures`].
    fn failed_at(&self, i: usize) {
        self.failed.fetch_add(1, Ordering::Relaxed);
        self.failures
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .push(i);
    }

    /// A problem as one line starting with the file's name (verify's problems start with it
    /// already, a FormatError too).
    fn named(&self, what: String) -> String {
        let prefix = format!("{}: ", self.set.path().display());
        format!("{prefix}{}", what.strip_prefix(&prefix).unwrap_or(&what))
    }

    /// Checks `tiles` on every core at every level (see [`Terrain::check`]).
    pub fn check_all(&self, tiles: &[usize]) {
        use rayon::prelude::*;
        tiles.par_iter().for_each(|&i| {
            let _ = self.check(i);
        });
    }

    /// Checks `tiles` on every core, each through its level (see [`Terrain::check_through`]).
    /// A single tile is checked on the calling thread, and none costs nothing: handing work to
    /// rayon's pool waits for a free worker, and the thread that checks ahead of need may hold
    /// them all, a tile's check each.
    pub fn check_all_through(&self, tiles: &[(usize, u32)]) {
        use rayon::prelude::*;
        match tiles {
            [] => {}
            &[(i, level)] => {
                let _ = self.check_through(i, level);
            }
            _ => tiles.par_iter().for_each(|&(i, level)| {
                let _ = self.check_through(i, level);
            }),
        }
    }

    /// The tiles that failed their check since the last call, with their problems.
    pub fn take_failures(&self) -> Vec<(usize, String)> {
        let taken = std::mem::take(
            &mut *self
                .failures
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner()),
        );
        taken
            .into_iter()
            .map(|i| {
                let problem = self.check(i).err().unwrap_or("failed its check");
                (i, problem.to_string())
            })
            .collect()
    }

    /// How many tiles have failed their check so far.
    pub fn failed_count(&self) -> usize {
        self.failed.load(Ordering::Relaxed)
    }

    /// Asks for tile `i` to be checked through `level` ahead of need, by the thread running
    /// [`Terrain::check_ahead`] (the prefetcher's predicted tiles). Cheap, and a no-op for a
    /// tile checked that far already.
    pub fn check_soon(&self, i: usize, level: u32) {
        if self
            .tiles
            .get(i)
            .is_none_or(|t| t.usable_at(level).is_some())
        {
            return;
        }
        let mut ahead = self.ahead.lock().unwrap_or_else(|p| p.into_inner());
        match ahead.iter_mut().find(|(j, _)| *j == i) {
            Some((_, queued)) => *queued = (*queued).max(level),
            None => {
                // A bounded queue: the newest predictions matter, the oldest may be stale.
                if ahead.len() >= 256 {
                    ahead.pop_front();
                }
                ahead.push_back((i, level));
                self.ahead_ready.notify_one();
            }
        }
    }

    /// Asks for `tiles` to be checked (each through its level) ahead of need before anything
    /// else waiting, the first of them first: tiles a frame wants now and draws an ancestor in
    /// place of, or a coarser level of, until they pass (`vkterrain --pyramid`).
    pub fn check_first(&self, tiles: &[(usize, u32)]) {
        let mut ahead = self.ahead.lock().unwrap_or_else(|p| p.into_inner());
        for &(i, level) in tiles.iter().rev() {
            if self
                .tiles
                .get(i)
                .is_none_or(|t| t.usable_at(level).is_some())
            {
                continue;
            }
            let queued = ahead.iter().find(|(j, _)| *j == i).map_or(0, |&(_, l)| l);
            ahead.retain(|&(j, _)| j != i);
            ahead.push_front((i, level.max(queued)));
        }
        ahead.truncate(256);
        self.ahead_ready.notify_one();
    }

    /// Checks the tiles [`Terrain::check_first`] and [`Terrain::check_soon`] ask for, from the
    /// front of the queue, as many at once as rayon has threads, until `stop` is set (then
    /// returns within a few milliseconds, after the checks in progress). Run on a thread of its
    /// own beside the frames, so that tiles come into view already checked.
    pub fn check_ahead(&self, stop: &AtomicBool) {
        use rayon::prelude::*;
        // As many at once as rayon has threads: the frames' own CPU work shares the cores.
        let batch = rayon::current_num_threads().max(1);
        while !stop.load(Ordering::Acquire) {
            let next: Vec<(usize, u32)> = {
                let mut ahead = self.ahead.lock().unwrap_or_else(|p| p.into_inner());
                if ahead.is_empty() {
                    ahead = self
                        .ahead_ready
                        .wait_timeout(ahead, Duration::from_millis(5))
                        .unwrap_or_else(|p| p.into_inner())
                        .0;
                }
                let n = ahead.len().min(batch);
                ahead.drain(..n).collect()
            };
            next.par_iter().for_each(|&(i, level)| {
                let _ = self.check_through(i, level);
            });
        }
    }

    /// Runs `f` with a thread checking tiles ahead of need beside it ([`Terrain::check_ahead`]).
    pub fn with_checks_ahead<R>(&self, f: impl FnOnce() -> R) -> R {
        /// Stops the thread when `f` returns or unwinds (the scope waits for it either way).
        struct Stop<'a>(&'a AtomicBool, &'a Condvar);
        impl Drop for Stop<'_> {
            fn drop(&mut self) {
                self.0.store(true, Ordering::Release);
                self.1.notify_all();
            }
        }
        let stop = AtomicBool::new(false);
        std::thread::scope(|s| {
            s.spawn(|| self.check_ahead(&stop));
            let _stop = Stop(&stop, &self.ahead_ready);
            f()
        })
    }

    /// The tile's own check (see [`Terrain::check_through`]), made once, with the semantic
    /// checks of levels `0..=level` if it is made now.
    fn own<'a>(&self, tile: &'a TileInfo, level: u32) -> &'a Result<Paged, String> {
        tile.own.get_or_init(|| {
            let paged = match &tile.broken {
                Some(problem) => Err(problem.clone()),
                None => paged(self.set_of(tile), tile, level),
            };
            let paged = paged.map_err(|what| self.named(what));
            if paged.is_ok() {
                tile.checked.store(level + 1, Ordering::Release);
            }
            paged
        })
    }

    /// Whether `tile` may be drawn: its own check (through `level` if made now), then its sides
    /// against its neighbours' at the levels that check read.
    fn usable(&self, tile: &TileInfo, level: u32) -> Result<(), String> {
        let mine = self.own(tile, level).as_ref().map_err(Clone::clone)?;
        let borders = &mine.sides().borders;
        self.sides_agree(tile, borders, 0..borders.len())
    }

    /// Where the set shares sides: whether `tile`'s sides at `levels` (`mine`, per level) are
    /// its neighbours' at those levels, and the tiles' morph units the same.
    fn sides_agree(
        &self,
        tile: &TileInfo,
        mine: &Borders,
        levels: std::ops::Range<usize>,
    ) -> Result<(), String> {
        if !self.sides_claimed || levels.is_empty() {
            return Ok(());
        }
        let units = |t: &TileInfo| -> Vec<u32> {
            t.levels.iter().map(|l| l.morph_unit.to_bits()).collect()
        };
        let count = levels.end as u32;
        for side in Side::ALL {
            let Some(j) = self.neighbour(tile, side) else {
                continue;
            };
            let b = &self.tiles[j];
            let differs = |theirs: &Borders| {
                units(tile) != units(b)
                    || levels.clone().any(|level| {
                        let rebased: Option<Vec<u32>> = theirs
                            .get(level)
                            .map_or(&[][..], |t| &t[side.opposite().index()])
                            .iter()
                            .map(|&p| rebase(p, side, b, tile))
                            .collect();
                        rebased.as_ref() != Some(&mine[level][side.index()])
                    })
            };
            // The neighbour's sides: from its own check where it has had one that read these
            // levels, else read from its data alone (a neighbour the cut never draws need not
            // be checked whole): as stored, unchecked (its sides' few pages; a compact tile's
            // levels decoded, not rebuilt); only where those differ from this tile's, again
            // with its checksum and structure, so that damage to the neighbour is not taken
            // for this tile's (a neighbour whose data do not read is never drawn).
            let set = self.set_of(b);
            let differs = match b.own.get().map(|own| own.as_ref().map(Paged::sides)) {
                Some(Err(_)) => false,
                Some(Ok(theirs)) if theirs.borders.len() >= levels.end => differs(&theirs.borders),
                _ => {
                    let stored = set.stored_sides(b.tx, b.ty, count).ok();
                    stored.is_none_or(|s| differs(&s))
                        && set
                            .tile_levels(b.tx, b.ty, 0..count)
                            .is_ok_and(|data| data.side_points(count).is_none_or(|s| differs(&s)))
                }
            };
            if differs {
                return Err(format!(
                    "{}: tile {},{}: its {side:?} side differs from tile {},{}'s, in a set built with shared sides (corrupted file)",
                    self.set.path().display(),
                    tile.tx,
                    tile.ty,
                    b.tx,
                    b.ty
                ));
            }
        }
        Ok(())
    }

    /// The tile across `side` of `tile`, if the set has one.
    pub fn neighbour(&self, tile: &TileInfo, side: Side) -> Option<usize> {
        self.tiles.at(tile.layer, tile.tx, tile.ty, side.step())
    }

    /// What each tile costs in GPU memory, level by level (the memory manager's view). A
    /// block's morph rows (its stored offsets to the coarser levels) count, and so travel and
    /// take pool memory, only with `morph_rows`: the vertex shaders that read them are
    /// `--morph-shader two-levels` and `forward-differences`. The morph pass places every
    /// vertex from its parents' own heights and discrete levels read none, so by default a
    /// level sends its positions alone. With `decode` a compact set's levels travel as their
    /// streams ([`Terrain::level_stream`]), decoded on the GPU into the positions.
    pub fn costs(&self, morph_rows: bool, decode: bool) -> Vec<memory::TileCost> {
        (0..self.tiles.len())
            .map(|i| {
                let t = self.tiles.outline(i);
                cost_of(&t.levels, &t.streams, morph_rows, decode)
            })
            .collect()
    }

    /// The stored bytes of one part of a tile, once the part's level has passed its check
    /// (None before, or when the tile failed).
    pub fn part(&self, tile: usize, part: memory::Part) -> Option<&[u8]> {
        let info = self.tiles.get(tile)?;
        let (memory::Part::Positions(level)
        | memory::Part::Morph(level)
        | memory::Part::Indices(level)) = part;
        if info.usable_at(level) != Some(true) {
            return None;
        }
        let blob = self
            .set_of(info)
            .blob_through(info.tx, info.ty, level + 1)?;
        let (offset, len) = match part {
            memory::Part::Positions(j) => {
                let l = info.levels.get(j as usize)?;
                (l.positions_offset, 4 * u64::from(l.block_len))
            }
            memory::Part::Morph(j) => {
                let l = info.levels.get(j as usize)?;
                (l.morph_offset, u64::from(j) * u64::from(l.block_len))
            }
            memory::Part::Indices(j) => {
                let l = info.levels.get(j as usize)?;
                (
                    l.index_offset,
                    u64::from(l.index_count) * u64::from(l.index_width),
                )
            }
        };
        let start = offset as usize;
        blob.get(start..start.checked_add(usize::try_from(len).ok()?)?)
    }

    /// Whether the set's levels can travel as compact streams (version 5 compact sets).
    pub fn has_streams(&self) -> bool {
        self.set.has_level_streams()
    }

    /// Level `level`'s compact stream of `tile` (version 5 compact sets), once the level has
    /// passed its check (None before, or when the tile failed): the check decoded the tile's
    /// levels through it and found each ending where its length says.
    pub fn level_stream(&self, tile: usize, level: u32) -> Option<&[u8]> {
        let info = self.tiles.get(tile)?;
        if info.usable_at(level) != Some(true) {
            return None;
        }
        self.set_of(info).level_stream(info.tx, info.ty, level)
    }

    /// The BC1 blocks of texture mip `mip` of `tile`, once the tile has passed its check.
    pub fn texture_mip(&self, tile: usize, mip: u32) -> Option<&[u8]> {
        let info = self.tiles.get(tile)?;
        if info.usable() != Some(true) {
            return None;
        }
        let range = info.paged()?.texture_mips.get(mip as usize)?.clone();
        self.set_of(info).texture_blob(info.tx, info.ty)?.get(range)
    }

    /// Where the camera at `p` is for the shader: its tile (column, row of tiles) and its
    /// position relative to that tile's north-west corner. Positions are expressed relative to
    /// that tile, from integers, so a grid point shared by two tiles lands on the same f32 in
    /// both.
    pub fn camera_tile(&self, p: DVec3) -> ((f64, f64), DVec3) {
        let (sx, sy) = self.spacing;
        let cells = f64::from(TILE_CELLS);
        let tile = ((p.x / (cells * sx)).floor(), (-p.y / (cells * sy)).floor());
        let relative = DVec3::new(p.x - tile.0 * cells * sx, p.y + tile.1 * cells * sy, p.z);
        (tile, relative)
    }

    /// A tile's first sample relative to the camera's tile `camera_tile` (columns, rows of
    /// base samples): its record's `tile_offset`. A layer tile's first sample is its column
    /// and row of layer tiles times `2^layer` base tiles.
    pub fn tile_offset(camera_tile: (f64, f64), tile: &TileInfo) -> [i32; 2] {
        let cells = f64::from(TILE_CELLS);
        let f = f64::from(1u32 << tile.layer);
        [
            ((f64::from(tile.tx) * f - camera_tile.0) * cells) as i32,
            ((f64::from(tile.ty) * f - camera_tile.1) * cells) as i32,
        ]
    }

    /// The base grid's tile at column `tx`, row `ty`.
    pub fn tile_index(&self, tx: u32, ty: u32) -> Option<usize> {
        self.tile_in(0, tx, ty)
    }

    /// World bounds of the whole dataset: its grid's extent, and the heights its header
    /// records (the source's range after void filling, which every level's surface keeps
    /// within its error of), without reading a tile.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let h = self.set.header();
        let (w, n) = (
            f64::from(h.grid_width.max(1) - 1),
            f64::from(h.grid_height.max(1) - 1),
        );
        (
            DVec3::new(0.0, -n * h.spacing_y, f64::from(h.height_min)),
            DVec3::new(w * h.spacing_x, 0.0, f64::from(h.height_max)),
        )
    }

    /// The highest ground within `radius` metres of (x, y), from the coarse height maps of the
    /// tiles there (each read from its tile's positions the first time it is needed). In a set
    /// with a pyramid, from the coarsest layer whose map's cells are at most half the radius
    /// ([`Terrain::max_height_near_in`]), whether or not the terrain opened its layers, so that
    /// a flyover over a wide set reads a few tiles a key rather than hundreds, and flies the
    /// same path either way.
    pub fn max_height_near(&self, x: f64, y: f64, radius: f64) -> f64 {
        let cell =
            f64::from(TILE_SIZE as u32) / HEIGHT_CELLS as f64 * self.spacing.0.max(self.spacing.1);
        let p = (0..=self.set.pyramid_layers())
            .take_while(|&p| cell * f64::from(1u32 << p) <= radius / 2.0)
            .last()
            .unwrap_or(0);
        if p > 0 {
            if let Some(z) = self.max_height_near_in(p, x, y, radius) {
                return z;
            }
        }
        let mut best = f64::NEG_INFINITY;
        let (sx, sy) = self.spacing;
        let tile_w = f64::from(TILE_CELLS) * sx;
        let tile_h = f64::from(TILE_CELLS) * sy;
        // Tiles whose box may meet the square (x, y) ± radius: columns east, rows south.
        let clamp_to = |v: f64, n: u32| v.floor().clamp(0.0, f64::from(n.max(1) - 1)) as u32;
        let (c0, c1) = (
            clamp_to((x - radius) / tile_w, self.tiles_x),
            clamp_to((x + radius) / tile_w, self.tiles_x),
        );
        let (r0, r1) = (
            clamp_to(-(y + radius) / tile_h, self.tiles_y),
            clamp_to(-(y - radius) / tile_h, self.tiles_y),
        );
        for ty in r0..=r1 {
            for tx in c0..=c1 {
                let Some(t) = self.tile_index(tx, ty).map(|i| &self.tiles[i]) else {
                    continue;
                };
                if t.max.x < x - radius
                    || t.min.x > x + radius
                    || t.max.y < y - radius
                    || t.min.y > y + radius
                {
                    continue;
                }
                let heights = t
                    .heights
                    .get_or_init(|| coarse_heights(&self.set, t.tx, t.ty));
                for cy in 0..HEIGHT_CELLS {
                    for cx in 0..HEIGHT_CELLS {
                        let h = heights[cy * HEIGHT_CELLS + cx];
                        if h == f32::NEG_INFINITY {
                            continue;
                        }
                        let cell = 257.0 / HEIGHT_CELLS as f64;
                        let x0 = t.min.x + cx as f64 * cell * sx;
                        let y1 = t.max.y - cy as f64 * cell * sy;
                        let (x1, y0) = (x0 + cell * sx, y1 - cell * sy);
                        if x1 >= x - radius
                            && x0 <= x + radius
                            && y1 >= y - radius
                            && y0 <= y + radius
                        {
                            best = best.max(f64::from(h));
                        }
                    }
                }
            }
        }
        if best.is_finite() {
            best
        } else {
            self.bounds().1.z
        }
    }

    /// [`Terrain::max_height_near`] from pyramid layer `p`'s coarse height maps, each cell's
    /// highest vertex raised by its tile's decimation error (its vertices are base samples, and
    /// its surface lies within that error of every base sample under it); None where the layer
    /// holds no tile there.
    fn max_height_near_in(&self, p: u32, x: f64, y: f64, radius: f64) -> Option<f64> {
        let layer = self.set.layer(p)?;
        let (tiles_x, tiles_y) = (layer.header().tiles_x, layer.header().tiles_y);
        let f = f64::from(1u32 << p);
        let (sx, sy) = (self.spacing.0 * f, self.spacing.1 * f);
        let (tile_w, tile_h) = (f64::from(TILE_CELLS) * sx, f64::from(TILE_CELLS) * sy);
        let clamp_to = |v: f64, n: u32| v.floor().clamp(0.0, f64::from(n.max(1) - 1)) as u32;
        let mut best = f64::NEG_INFINITY;
        for ty in
            clamp_to(-(y + radius) / tile_h, tiles_y)..=clamp_to(-(y - radius) / tile_h, tiles_y)
        {
            for tx in
                clamp_to((x - radius) / tile_w, tiles_x)..=clamp_to((x + radius) / tile_w, tiles_x)
            {
                let heights = {
                    let mut maps = self.layer_heights.lock().unwrap_or_else(|e| e.into_inner());
                    *maps.entry((p, tx, ty)).or_insert_with(|| {
                        let raise = layer.decimation_error(tx, ty).unwrap_or(0.0);
                        coarse_heights(&layer, tx, ty).map(|h| h + raise)
                    })
                };
                let (x_west, y_north) = (f64::from(tx) * tile_w, -f64::from(ty) * tile_h);
                let cell = 257.0 / HEIGHT_CELLS as f64;
                for (k, &h) in heights.iter().enumerate() {
                    let (cx, cy) = ((k % HEIGHT_CELLS) as f64, (k / HEIGHT_CELLS) as f64);
                    let x0 = x_west + cx * cell * sx;
                    let y1 = y_north - cy * cell * sy;
                    let (x1, y0) = (x0 + cell * sx, y1 - cell * sy);
                    if h > f32::NEG_INFINITY
                        && x1 >= x - radius
                        && x0 <= x + radius
                        && y1 >= y - radius
                        && y0 <= y + radius
                    {
                        best = best.max(f64::from(h));
                    }
                }
            }
        }
        best.is_finite().then_some(best)
    }
}

/// What a tile of levels `levels` (compact streams `streams`) costs in GPU memory, level by
/// level (see [`Terrain::costs`]).
pub fn cost_of(
    levels: &[LevelEntry],
    streams: &[u32],
    morph_rows: bool,
    decode: bool,
) -> memory::TileCost {
    memory::TileCost {
        levels: levels
            .iter()
            .enumerate()
            .map(|(i, l)| memory::LevelCost {
                positions: 4 * u64::from(l.block_len),
                morph: if morph_rows {
                    i as u64 * u64::from(l.block_len)
                } else {
                    0
                },
                indices: u64::from(l.index_count) * u64::from(l.index_width),
                index_width: l.index_width,
                stream: streams.get(i).filter(|_| decode).map(|&n| u64::from(n)),
            })
            .collect(),
    }
}

/// A tile's own check, and what it reads: the tile's checksum, its structure and the problems
/// `tiletool verify` (without a source) would report at levels `0..=level`, the texture, and
/// the level table read at open still the one stored.
fn paged(set: &TileSet, info: &TileInfo, level: u32) -> Result<Paged, String> {
    let (tx, ty) = (info.tx, info.ty);
    let tile = set
        .tile_levels(tx, ty, 0..level + 1)
        .map_err(|e| e.to_string())?;
    let checked = tiles::verify::tile_problems_in(set, &tile, 0..level + 1);
    if let Some(problem) = checked.into_iter().next() {
        return Err(problem);
    }
    let texture_mips = match set.texture(tx, ty).map_err(|e| e.to_string())? {
        Some(t) => t
            .mips
            .iter()
            .map(|(e, _)| e.offset as usize..(e.offset + e.len) as usize)
            .collect(),
        None => Vec::new(),
    };
    let sides = sides(&tile).ok_or("a border names a vertex outside its blocks")?;
    Ok(Paged {
        sides: RwLock::new(Arc::new(sides)),
        texture_mips,
        parts: RwLock::new(Arc::new(tiles::parts::tables_through(&tile, level + 1))),
    })
}

/// Per level, the vertex indices on the tile's N, E, S, W sides and the packed vertices there.
type Borders = Vec<[Vec<u32>; 4]>;

/// A tile's sides at each level it holds (every level, or a compact tile's levels rebuilt so
/// far): [`Borders`] as vertices and as indices (None where a side names a vertex no block
/// holds: data not checked).
fn sides(tile: &tiles::format::Tile) -> Option<Sides> {
    let levels = tile.levels().len() as u32;
    let border_indices: Borders = (0..levels)
        .filter_map(|i| tile.level(i))
        .map(|l| l.border.map(|side| side.to_vec()))
        .collect();
    Some(Sides {
        borders: tile.side_points(levels)?,
        border_indices,
    })
}

/// A tile's coarse height map: the highest vertex in each cell, from its positions as stored
/// (unchecked: the map only places cameras; a compact tile's decoded, not rebuilt).
fn coarse_heights(set: &TileSet, tx: u32, ty: u32) -> [f32; HEIGHT_CELLS * HEIGHT_CELLS] {
    let mut heights = [f32::NEG_INFINITY; HEIGHT_CELLS * HEIGHT_CELLS];
    let Ok(points) = set.tile_points(tx, ty) else {
        return heights;
    };
    for (x, y, h) in points {
        let (x, y) = ((x as usize).min(256), (y as usize).min(256));
        let cell = (y * HEIGHT_CELLS / 257) * HEIGHT_CELLS + x * HEIGHT_CELLS / 257;
        heights[cell] = heights[cell].max(h);
    }
    heights
}
