//! The page's files, inside the binary: the console works with no network but its own.

/// Every file served under `/assets/` (and `index.html`, `login.html` at `/` and `/login`), with
/// its content type.
const FILES: &[(&str, &str, &[u8])] = &[
    (
        "index.html",
        "text/html; charset=utf-8",
        include_bytes!("../assets/index.html"),
    ),
    (
        "login.html",
        "text/html; charset=utf-8",
        include_bytes!("../assets/login.html"),
    ),
    (
        "console.css",
        "text/css; charset=utf-8",
        include_bytes!("../assets/console.css"),
    ),
    (
        "console.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/console.js"),
    ),
    (
        "widgets.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/widgets.js"),
    ),
    (
        "inputs.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/inputs.js"),
    ),
    (
        "designer.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../assets/designer.js"),
    ),
];

/// The content type and bytes of file `name`.
pub fn get(name: &str) -> Option<(&'static str, &'static [u8])> {
    FILES
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, mime, body)| (*mime, *body))
}

/// Every file's name.
pub fn names() -> impl Iterator<Item = &'static str> {
    FILES.iter().map(|(n, _, _)| *n)
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_file_the_pages_load_is_embedded() {
        for page in ["index.html", "login.html"] {
            let (_, body) = super::get(page).unwrap();
            let text = String::from_utf8_lossy(body);
            for part in text.split("/assets/").skip(1) {
                let name: String = part
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'))
                    .collect();
                assert!(super::get(&name).is_some(), "{page} loads {name}");
            }
        }
        // nothing is fetched from elsewhere (the SVG namespace is a name, not a fetch)
        for name in super::names() {
            let text = String::from_utf8_lossy(super::get(name).unwrap().1)
                .replace("http://www.w3.org/2000/svg", "");
            assert!(
                !text.contains("http://") && !text.contains("https://"),
                "{name}"
            );
        }
    }
}
