//! Downloading a file shared on Google Drive: `download?id=ID&export=download` on Drive's
//! download server answers a small file at once, and a large one (which Drive cannot scan for
//! viruses) with a page whose form (`id="download-form"`) holds the fields (`id`, `export`,
//! `confirm`, `uuid`) of the request that sends the file.
//!
//! Design decision: the name Drive states decides which file an id is (the page names it, the
//! file's `Content-Disposition` does too), so a catalog entry may list several ids (a release
//! script's, without names) and the wrong ones are skipped before their bodies are read; the
//! body is resumed with a range like every other download.

use std::path::Path;

use dgstereo_core::{Error, Result};

use crate::catalog::Sources;
use crate::http::{Http, Saved, join};
use crate::options::FetchOptions;

/// What one id turned out to be.
enum Outcome {
    /// The file, now in the partial file.
    Saved,
    /// Another file: its name.
    Other(String),
}

/// Downloads the Drive file called `file`, one of `ids`, into `partial` (resuming the bytes
/// there); returns the address it came from.
pub(crate) fn download(
    sources: &Sources,
    (file, ids): (&str, &[&str]),
    partial: &Path,
    http: &Http,
    options: &FetchOptions,
) -> Result<String> {
    // With one id an unnamed answer is taken; among several only a named one is.
    let need_name = ids.len() > 1;
    let mut others = Vec::new();
    for id in ids {
        let url = sources.google_drive_file(id);
        match fetch_id(&url, file, need_name, partial, http, options)? {
            Outcome::Saved => return Ok(url),
            Outcome::Other(name) => others.push(format!("{id}: {name}")),
        }
    }
    let first = sources.google_drive_file(ids.first().copied().unwrap_or_default());
    Err(Error::fetch(first, format!("none of the Google Drive files it may be is {file} ({})", others.join(", "))))
}

fn fetch_id(
    url: &str,
    file: &str,
    need_name: bool,
    partial: &Path,
    http: &Http,
    options: &FetchOptions,
) -> Result<Outcome> {
    let have = std::fs::metadata(partial).map(|m| m.len()).unwrap_or(0);
    let first = http.get(url, have, true)?;
    let answer = if is_page(&first) {
        let page = read_page(first, url)?;
        if let Some(name) = page_file_name(&page).filter(|n| n != file) {
            return Ok(Outcome::Other(name));
        }
        let confirmed = confirmation_url(&page, url).ok_or_else(|| {
            Error::fetch(
                url,
                format!("Google Drive sent a page, not the file, and no download form: {}", page_message(&page)),
            )
        })?;
        let answer = http.get(&confirmed, have, true)?;
        if is_page(&answer) {
            let page = read_page(answer, &confirmed)?;
            return Err(Error::fetch(&confirmed, format!("Google Drive sent a page again: {}", page_message(&page))));
        }
        (answer, confirmed)
    } else {
        (first, url.to_string())
    };
    let (response, from) = answer;
    match response.header("Content-Disposition").and_then(disposition_file_name) {
        Some(name) if name != file => return Ok(Outcome::Other(name)),
        None if need_name && response.status() != 416 => {
            return Ok(Outcome::Other("a file whose name Google Drive does not state".to_string()));
        }
        _ => {}
    }
    if http.save(response, &from, partial, have, file, options)? == Saved::Restart {
        http.download(&from, partial, file, options)?;
    }
    Ok(Outcome::Saved)
}

fn is_page(response: &ureq::Response) -> bool {
    response.status() != 416 && response.content_type().eq_ignore_ascii_case("text/html")
}

/// The page's text, at most 1 MiB of it.
fn read_page(response: ureq::Response, url: &str) -> Result<String> {
    use std::io::Read;
    let mut bytes = Vec::new();
    response
        .into_reader()
        .take(1 << 20)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::fetch(url, format!("reading Google Drive's page: {e}")))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// The file a confirmation page names (`<span class="uc-name-size"><a ...>NAME</a> (SIZE)`).
fn page_file_name(page: &str) -> Option<String> {
    let span = &page[page.find("uc-name-size")?..];
    let link = &span[span.find("<a")?..];
    let text = &link[link.find('>')? + 1..];
    Some(unescape(text[..text.find('<')?].trim())).filter(|n| !n.is_empty())
}

/// The page's title and error line, for an error message.
fn page_message(page: &str) -> String {
    let between = |open: &str, close: &str| {
        let start = page.find(open)? + open.len();
        let end = page[start..].find(close)? + start;
        Some(unescape(page[start..end].trim()))
    };
    let title = between("<title>", "</title>").unwrap_or_else(|| "an untitled page".to_string());
    match between("class=\"uc-error-subcaption\">", "<") {
        Some(detail) if !detail.is_empty() => format!("'{title}': {detail}"),
        _ => format!("'{title}'"),
    }
}

/// The address the page's download form sends: its `action` (relative to `url` where it is
/// relative) with its input fields, in their order, as the query.
fn confirmation_url(page: &str, url: &str) -> Option<String> {
    let form_start = page.find("id=\"download-form\"").and_then(|at| page[..at].rfind("<form"))?;
    let form_end = page[form_start..].find("</form>").map_or(page.len(), |e| form_start + e);
    let form = &page[form_start..form_end];
    let tag_end = form.find('>')?;
    let action = attribute(&form[..tag_end], "action")?;
    let mut fields = Vec::new();
    let mut rest = &form[tag_end..];
    while let Some(at) = rest.find("<input") {
        let tag = &rest[at..];
        let tag = &tag[..tag.find('>').unwrap_or(tag.len())];
        if let (Some(name), Some(value)) = (attribute(tag, "name"), attribute(tag, "value")) {
            fields.push(format!("{}={}", encode(&name), encode(&value)));
        }
        rest = &rest[at + tag.len()..];
    }
    if !fields.iter().any(|f| f.starts_with("confirm=")) {
        return None;
    }
    let base = join(url, &action);
    let separator = if base.contains('?') { '&' } else { '?' };
    Some(format!("{base}{separator}{}", fields.join("&")))
}

/// The value of attribute `name` in the tag text `tag` (double or single quotes).
fn attribute(tag: &str, name: &str) -> Option<String> {
    let mut search = tag;
    loop {
        let at = search.find(name)?;
        let before = search[..at].chars().next_back();
        let after = search[at + name.len()..].trim_start();
        search = &search[at + name.len()..];
        if before.is_some_and(|c| !c.is_whitespace()) {
            continue;
        }
        let Some(value) = after.strip_prefix('=') else { continue };
        let value = value.trim_start();
        let quote = value.chars().next()?;
        if quote != '"' && quote != '\'' {
            continue;
        }
        let inner = &value[1..];
        return Some(unescape(&inner[..inner.find(quote)?]));
    }
}

/// The file name a `Content-Disposition` header states (`filename*=UTF-8''NAME` first).
fn disposition_file_name(header: &str) -> Option<String> {
    let parts: Vec<&str> = header.split(';').map(str::trim).collect();
    if let Some(encoded) = parts.iter().find_map(|p| p.strip_prefix("filename*=")) {
        let value = encoded.split_once("''").map_or(encoded, |(_, v)| v);
        return Some(decode(value.trim_matches('"')));
    }
    parts.iter().find_map(|p| p.strip_prefix("filename=")).map(|v| v.trim_matches('"').to_string())
}

fn unescape(text: &str) -> String {
    text.replace("&quot;", "\"").replace("&#39;", "'").replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&")
}

/// `text` percent-encoded for a query (everything but unreserved characters).
fn encode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// `text` with its percent-escapes decoded (invalid ones kept as they are).
fn decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex =
            (bytes[i] == b'%').then(|| text.get(i + 1..i + 3)).flatten().and_then(|h| u8::from_str_radix(h, 16).ok());
        match hex {
            Some(b) => {
                out.push(b);
                i += 3;
            }
            None => {
                out.push(bytes[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAGE: &str = r#"<!DOCTYPE html><html><head><title>Google Drive - Virus scan warning</title></head><body>
<p class="uc-warning-subcaption">Google Drive can't scan this file for viruses.</p>
<span class="uc-name-size"><a href="/open?id=ABC">defomstereo_vitl_kitti.pth</a> (1.4G)</span>
<form id="download-form" action="https://drive.usercontent.google.com/download" method="get">
<input type="submit" id="uc-download-link" value="Download anyway">
<input type="hidden" name="id" value="ABC"><input type="hidden" name="export" value="download">
<input type="hidden" name="confirm" value="t"><input type="hidden" name="uuid" value="d3a1-&amp;x">
</form></body></html>"#;

    #[test]
    fn the_confirmation_page_gives_the_name_and_the_confirmed_request() {
        assert_eq!(page_file_name(PAGE).as_deref(), Some("defomstereo_vitl_kitti.pth"));
        assert_eq!(
            confirmation_url(PAGE, "https://drive.usercontent.google.com/download?id=ABC&export=download").as_deref(),
            Some("https://drive.usercontent.google.com/download?id=ABC&export=download&confirm=t&uuid=d3a1-%26x")
        );
        let relative = PAGE.replace("https://drive.usercontent.google.com/download", "/download");
        assert!(
            confirmation_url(&relative, "http://127.0.0.1:9/download?id=ABC")
                .unwrap()
                .starts_with("http://127.0.0.1:9/download?id=ABC&")
        );
        let quota = "<html><head><title>Google Drive - Quota exceeded</title></head><body>\
                     <p class=\"uc-error-subcaption\">Too many users have viewed or downloaded this file recently.</p></body></html>";
        assert_eq!(confirmation_url(quota, "http://x/"), None);
        assert!(page_message(quota).contains("Quota exceeded") && page_message(quota).contains("Too many users"));
    }

    #[test]
    fn content_disposition_names_the_file() {
        let header = "attachment; filename=\"a b.pth\"; filename*=UTF-8''a%20b.pth";
        assert_eq!(disposition_file_name(header).as_deref(), Some("a b.pth"));
        assert_eq!(disposition_file_name("attachment; filename=\"x.pth\"").as_deref(), Some("x.pth"));
        assert_eq!(disposition_file_name("inline"), None);
    }
}
