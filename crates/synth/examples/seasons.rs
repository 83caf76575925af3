//! Writes a procedural-world tile and its four built-in seasonal variants (with and without the
//! class map) as PNGs, with each variant's fidelity report:
//! `cargo run -p synth --example seasons -- <out_dir> [size] [seed]`.

use synth::fidelity::{check, FidelityParams};
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = std::path::PathBuf::from(
        args.next()
            .ok_or("usage: seasons <out_dir> [size] [seed]")?,
    );
    let size: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(256);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let world = world::generate(
        &world::WorldParams::new(size, seed),
        &world::Neutral,
        &|_, _| {},
    )?;
    raster::write_image(out.join("real.png"), &world.left.image)?;
    let model = BuiltinSeasons::new(seed);
    for (suffix, classes) in [("", Some(&world.left.classes)), ("_colour_only", None)] {
        let source = SourceImage {
            id: "world",
            image: &world.left.image,
            classes,
        };
        for season in Season::ALL {
            let variant = model.generate(&source, season)?;
            let report = check(&world.left.image, &variant, &FidelityParams::default())?;
            let path = out.join(format!("{season}{suffix}.png"));
            raster::write_image(&path, &variant)?;
            println!("{}: {report}", path.display());
        }
    }
    Ok(())
}
