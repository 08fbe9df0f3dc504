//! Closed-form flows with exact velocity gradients (and so exact Q).
