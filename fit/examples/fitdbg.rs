//! Fits a campaign and writes the table (debug helper): `fitdbg CAMPAIGN OUT`.
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let c = murk_campaign::Campaign::open(&a[1]).unwrap();
    let t0 = std::time::Instant::now();
    let f = murk_fit::FitParams::default()
        .check()
        .unwrap()
        .fit(&c)
        .unwrap();
    eprintln!("fit in {:?}", t0.elapsed());
    f.write(std::path::Path::new(&a[2])).unwrap();
    print!("{}", f.summary());
}
