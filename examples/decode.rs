//! Decodes image files with `rccar::imageio` (as `rccar detect`, `stages` and replay do) and
//! writes each as a PNG (`<out>/<stem>.png`, grey files stay grey): the Rust side of
//! `tests/parity/jpeg_parity.py`. Prints whether JPEG goes through libjpeg-turbo.
//!
//! `cargo run --release --features jpeg-turbo --example decode -- OUT FILE...`

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((out, files)) = args.split_first() else {
        eprintln!("usage: decode OUT FILE...");
        std::process::exit(2);
    };
    std::fs::create_dir_all(out).expect("output directory");
    println!("jpeg_like_opencv {}", rccar::imageio::JPEG_LIKE_OPENCV);
    let mut failed = 0;
    for f in files {
        let p = std::path::Path::new(f);
        match rccar::imageio::open(p) {
            Ok(img) => {
                let stem = p
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let dst = std::path::Path::new(out).join(format!("{stem}.png"));
                if let Err(e) = img.save(&dst) {
                    eprintln!("{}: {e}", dst.display());
                    failed += 1;
                }
            }
            Err(e) => {
                eprintln!("{e}");
                failed += 1;
            }
        }
    }
    std::process::exit(if failed > 0 { 1 } else { 0 });
}
