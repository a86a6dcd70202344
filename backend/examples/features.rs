fn main() {
    let g = parallax_backend::gpu::Gpu::new().unwrap();
    let f = g.device.features();
    println!("{} {:?}", g.info.name, g.info.device_type);
    println!(
        "FLOAT32_FILTERABLE: {}",
        f.contains(wgpu::Features::FLOAT32_FILTERABLE)
    );
    println!(
        "TIMESTAMP_QUERY: {}",
        f.contains(wgpu::Features::TIMESTAMP_QUERY)
    );
}
