//! The service's error: an HTTP status, the request field at fault and a message.

use crate::store::StoreError;

/// An error reply. 4xx name the request field at fault; 5xx are the server's own trouble (the
/// database, an LLM endpoint), never the request's.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{status} {field}: {message}")]
pub struct ApiError {
    /// HTTP status.
    pub status: u16,
    /// The field, e.g. `container` or `scene.containers[2].pose`; empty for the whole request.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl ApiError {
    /// An error with a status, field and message.
    pub fn new(status: u16, field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            status,
            field: field.into(),
            message: message.into(),
        }
    }

    /// A 500: something the server should not have run into.
    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(500, "", message)
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        Self::internal(e.to_string())
    }
}
