//! DEM readers (being written).
