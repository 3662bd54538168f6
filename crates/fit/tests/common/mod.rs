pub mod localise_records;

use fit::ExcitedRecord;
use motor_model::{Input, Record};

/// The output-error view of a logged record driven by `input`: its current and encoder angle,
/// nothing left out.
#[allow(dead_code)]
pub fn excited<'a>(rec: &'a Record, input: &'a Input) -> ExcitedRecord<'a> {
    ExcitedRecord {
        input,
        dt: rec.t[1] - rec.t[0],
        current: &rec.current,
        speed: None,
        position: rec.position.as_deref(),
        exclude_current: None,
        exclude_speed: None,
    }
}
