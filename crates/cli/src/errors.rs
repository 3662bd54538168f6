//! The two kinds of failure the exit code tells apart from any other: a fit that ran but is
//! not a result ([`NotConverged`], exit 3) and input the user has to fix ([`BadInput`], exit 2).

/// Marks a fit that did not converge, for the exit code.
#[derive(Debug)]
pub struct NotConverged(pub String);

impl std::fmt::Display for NotConverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NotConverged {}

/// Marks an error as the user's input to fix, for the exit code.
#[derive(Debug)]
pub struct BadInput(pub String);

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}
