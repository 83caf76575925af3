//! The tiles' files in the work folder: `tiles/<id>.json` (the record) and `tiles/<id>.tif`
//! (the cells). They make a run resumable and shardable: any process can tell which tiles are
//! finished from the folder alone.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::Result;
use camera::GridWindow;

use super::mosaic::{read_part, write_part};
use super::plan::Tile;
use super::tile::TileRecord;
use workflow::stage::write_json;

/// The `tiles/` folder of a work folder.
pub struct TileFolder {
    dir: PathBuf,
}

impl TileFolder {
    pub fn new(work: &Path) -> Self {
        TileFolder {
            dir: work.join("tiles"),
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn record_path(&self, tile: &Tile) -> PathBuf {
        self.dir.join(format!("{}.json", tile.id))
    }

    fn part_path(&self, tile: &Tile) -> PathBuf {
        self.dir.join(format!("{}.tif", tile.id))
    }

    /// A tile's record, if it has one for this plan (a record of another tiling is ignored).
    pub fn record(&self, tile: &Tile) -> Option<TileRecord> {
        let text = std::fs::read_to_string(self.record_path(tile)).ok()?;
        serde_json::from_str::<TileRecord>(&text)
            .ok()
            .filter(|r| r.tile == *tile)
    }

    /// Saves a tile's cells, then its record: a record is only there once its cells are.
    pub fn save(&self, tile: &Tile, record: &TileRecord, cells: Option<&GridWindow>) -> Result<()> {
        if let Some(cells) = cells {
            write_part(&self.part_path(tile), cells)?;
        }
        write_json(&self.record_path(tile), &serde_json::to_value(record)?)
    }

    /// The cells a finished tile saved on the grid's rows `rows` (`None` if it has none there).
    pub fn cells(
        &self,
        record: &TileRecord,
        cells: (usize, usize, usize, usize),
        rows: Range<usize>,
    ) -> Result<Option<GridWindow>> {
        read_part(&self.part_path(&record.tile), cells, rows)
    }

    /// The records of the plan's tiles, in plan order, and the ids of the tiles without one.
    pub fn records(&self, tiles: &[Tile]) -> (Vec<TileRecord>, Vec<String>) {
        let mut records = Vec::with_capacity(tiles.len());
        let mut missing = Vec::new();
        for t in tiles {
            match self.record(t) {
                Some(r) => records.push(r),
                None => missing.push(t.id.clone()),
            }
        }
        (records, missing)
    }
}
