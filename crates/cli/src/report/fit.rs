//! The `fit` report (`report.html`).
