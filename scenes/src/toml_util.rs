//! Parsing helpers that keep the file, task and field path in every error.

use crate::error::SceneError;
use serde::de::DeserializeOwned;

pub(crate) fn parse_table(text: &str, file: &str) -> Result<toml::Table, SceneError> {
    text.parse::<toml::Table>().map_err(|e| SceneError::Syntax {
        file: file.to_string(),
        message: e.to_string().trim_end().to_string(),
    })
}

/// Deserialises `value`, reporting the failing field's path (e.g. `object[1].mass`).
pub(crate) fn deserialize_at<T: DeserializeOwned>(
    value: toml::Value,
    file: &str,
    task: Option<&str>,
) -> Result<T, SceneError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let field = e.path().to_string();
        let field = if field == "." { "(root)".into() } else { field };
        // toml appends its own "in `a.b`" line, which the indexed path above already says.
        let message = e.into_inner().to_string();
        let message = message.lines().next().unwrap_or_default().to_string();
        SceneError::field(file, task, field, message)
    })
}
