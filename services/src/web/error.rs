//! Errors on the pages: an [`AppError`] shown as the site's HTML error page with the same status
//! (with the navigation when the caller is signed in), and the pages' own path and query
//! extractors, whose refusals are such pages too rather than the API's problem JSON.

use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use maud::{Markup, html};
use serde::de::DeserializeOwned;

use super::layout::page;
use crate::api::auth::{WebUser, signed_in};
use crate::api::error::{AppError, Problem};
use crate::api::extract::{ApiPath, ApiQuery};
use crate::api::state::AppState;
use crate::store::ApiKey;

/// An [`AppError`] as an HTML page with the same status; `user` adds the navigation.
pub struct WebError {
    err: AppError,
    /// Boxed: the error travels in every page handler's `Result`.
    user: Option<Box<ApiKey>>,
}

impl WebError {
    /// The error shown to this signed-in user (the page keeps its navigation).
    pub fn signed_in(mut self, user: &WebUser) -> Self {
        self.user = Some(Box::new(user.key.clone()));
        self
    }

    /// The error of a request whose session (if any) is not known yet.
    pub async fn of_request(err: AppError, parts: &Parts, st: &AppState) -> Self {
        WebError {
            err,
            user: signed_in(parts, st).await.map(Box::new),
        }
    }
}

impl From<AppError> for WebError {
    fn from(err: AppError) -> Self {
        WebError { err, user: None }
    }
}

impl From<crate::store::StoreError> for WebError {
    fn from(e: crate::store::StoreError) -> Self {
        WebError::from(AppError::from(e))
    }
}

/// The body of an error page: the problem's title and detail, and the way back.
pub fn error_body(p: &Problem) -> Markup {
    html! {
        h1 { (p.title) }
        p #detail { (p.detail) }
        p { a href="/fleet" { "Back to the fleet" } }
    }
}

impl IntoResponse for WebError {
    fn into_response(self) -> Response {
        if let AppError::Internal(e) = &self.err {
            tracing::error!(error = %e, "page failed");
        }
        let p = self.err.problem();
        let mut r = page(&p.title, self.user.as_deref(), error_body(&p));
        *r.status_mut() =
            StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        if let Some(s) = self.err.retry_after_s() {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        r
    }
}

/// Path parameters of a page; a malformed one (not UTF-8 once decoded) is the 400 page.
pub struct WebPath<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for WebPath<T> {
    type Rejection = WebError;

    async fn from_request_parts(parts: &mut Parts, st: &AppState) -> Result<Self, WebError> {
        match ApiPath::<T>::from_request_parts(parts, st).await {
            Ok(ApiPath(v)) => Ok(WebPath(v)),
            Err(e) => Err(WebError::of_request(e, parts, st).await),
        }
    }
}

/// The query string of a page; a malformed one is the 400 page.
pub struct WebQuery<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for WebQuery<T> {
    type Rejection = WebError;

    async fn from_request_parts(parts: &mut Parts, st: &AppState) -> Result<Self, WebError> {
        match ApiQuery::<T>::from_request_parts(parts, st).await {
            Ok(ApiQuery(v)) => Ok(WebQuery(v)),
            Err(e) => Err(WebError::of_request(e, parts, st).await),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn body_text(r: Response) -> String {
        let b = axum::body::to_bytes(r.into_body(), 1 << 20)
            .await
            .expect("body");
        String::from_utf8(b.to_vec()).expect("utf-8")
    }

    /// What a caller put in a path ends up in a problem's detail: markup in it is text on the
    /// page, in the body and in the title alike.
    #[tokio::test]
    async fn user_text_on_an_error_page_is_escaped() {
        let hostile = r#"<script>alert("x")</script> & 'q' <b onclick='y'>"#;
        let r = WebError::from(AppError::NotFound(format!("no trace `{hostile}`"))).into_response();
        assert_eq!(r.status(), StatusCode::NOT_FOUND);
        assert!(
            r.headers()[header::CONTENT_TYPE]
                .to_str()
                .is_ok_and(|c| c.starts_with("text/html"))
        );
        let html = body_text(r).await;
        assert!(
            html.contains(
                "no trace `&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &amp; 'q' \
                 &lt;b onclick='y'&gt;`"
            ),
            "{html}"
        );
        assert!(!html.contains("<script") && !html.contains("<b "), "{html}");
        assert!(html.contains("<h1>Not found</h1>"), "{html}");
        // Not signed in: no navigation, no sign-out form.
        assert!(!html.contains("/logout"), "{html}");
    }
}
