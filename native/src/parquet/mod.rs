//! Records and state samples as Arrow columns, for the Parquet outputs (analyzer/parquet/
//! and the fleet dataset's tables).

pub mod records;
pub mod states;
