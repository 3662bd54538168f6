//! The model file (SPEC section 8): an identified rig as one versioned JSON document, written by
//! `identify --save-model` and read by `simulate --model` and `replay --model`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::servo::plant::ServoRig;

/// The `format` field of every model file.
pub const MODEL_FILE_FORMAT: &str = "motorid-model";
/// The version this build writes and reads.
pub const MODEL_FILE_VERSION: u32 = 1;

/// An identified model as saved: the rig (motor at the output, gearing, loads, controller) and
/// the 95 % intervals of the fitted motor constants, by name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always [`MODEL_FILE_FORMAT`].
    pub format: String,
    /// [`MODEL_FILE_VERSION`] when written by this build.
    pub version: u32,
    /// The rig.
    pub rig: ServoRig,
    /// 95 % intervals `[lo, hi]` of the fitted constants by name (`ke`, `R`, `J`, `Fc`, `fv`,
    /// `mu_m`, `mu_l`), in the units of [`crate::ServoMotor`]'s fields, where the fit gave them.
    #[serde(default)]
    pub ci95: BTreeMap<String, [f64; 2]>,
    /// The records the model was identified from (file names as given), for the reader.
    #[serde(default)]
    pub identified_from: Vec<String>,
    /// Whether it was identified on the recorded duty (open loop): a replay then defaults to
    /// open loop too.
    #[serde(default)]
    pub open_loop: bool,
}

impl ModelFile {
    /// A model file of this version for `rig`.
    pub fn new(rig: ServoRig) -> Self {
        ModelFile {
            format: MODEL_FILE_FORMAT.to_string(),
            version: MODEL_FILE_VERSION,
            rig,
            ci95: BTreeMap::new(),
            identified_from: Vec::new(),
            open_loop: false,
        }
    }

    /// Refuses a document of another format or version, or an invalid rig (its motor, each
    /// load and the controller checked as their options are).
    pub fn check(&self) -> Result<(), ModelError> {
        if self.format != MODEL_FILE_FORMAT {
            return Err(ModelError::RigSpec {
                what: "model file",
                spec: self.format.clone(),
                reason: format!("`format` is not `{MODEL_FILE_FORMAT}`"),
            });
        }
        if self.version != MODEL_FILE_VERSION {
            return Err(ModelError::RigSpec {
                what: "model file",
                spec: format!("version {}", self.version),
                reason: format!(
                    "this motorid reads version {MODEL_FILE_VERSION}; identify the model again with this version"
                ),
            });
        }
        self.rig.validate()?;
        for load in &self.rig.loads {
            load.check()?;
        }
        match &self.rig.controller {
            Some(c) => c.check(),
            None => Ok(()),
        }
    }
}
