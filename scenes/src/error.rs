use std::fmt;

/// A scene or catalogue file that cannot be used, with where the problem is.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: not valid TOML: {message}")]
    Syntax { file: String, message: String },
    #[error("{0}")]
    Field(FieldError),
}

/// A bad or inconsistent value: file, task (when inside one), field path and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    pub file: String,
    pub task: Option<String>,
    pub field: String,
    pub message: String,
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.file)?;
        if let Some(task) = &self.task {
            write!(f, "task {task}: ")?;
        }
        write!(f, "field `{}`: {}", self.field, self.message)
    }
}

impl SceneError {
    pub fn field(
        file: &str,
        task: Option<&str>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        SceneError::Field(FieldError {
            file: file.to_string(),
            task: task.map(str::to_string),
            field: field.into(),
            message: message.into(),
        })
    }
}
