pub mod localise_records;
