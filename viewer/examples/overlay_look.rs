use qbricks_viewer::{
    film,
    mesh::Meshes,
    overlay,
    render::{Renderer, Scene},
    view_state::ViewState,
    volume::Volume,
};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::Path::new(&args[1]);
    let (w, h): (u32, u32) = (args[2].parse().unwrap(), args[3].parse().unwrap());
    let out = &args[4];
    let view = format::BrickFileView::open(path).unwrap();
    let vol = Volume::new(&view).unwrap();
    let mut st = ViewState::default_for_volume(&vol);
    st.width = w;
    st.height = h;
    if args.len() > 5 {
        st.camera.projection = qbricks_viewer::camera::Projection::Orthographic {
            width: args[5].parse().unwrap(),
        };
    }
    let meshes = Meshes::empty();
    let scene = Scene::new(&vol, &st, &meshes).unwrap();
    let r = Renderer::new(None).unwrap();
    let f = r.render(&scene);
    let mut px = film::to_rgb8(&f.rgb);
    let t = std::time::Instant::now();
    let info = overlay::OverlayInfo {
        rays: st.camera.ray_generator(w, h),
        pivot: st.camera.look_at,
        bounds: Some((vol.to_world(vol.bounds_min), vol.to_world(vol.bounds_max))),
        depth: None,
        legend: Some(overlay::LegendInfo {
            colormap: &st.colormap,
            iso_field: &st.iso_field,
            isos: &[st.iso],
        }),
        title: Some("wake_small.qbk"),
        background: st.background,
    };
    let all: overlay::Overlays = std::env::var("OV")
        .unwrap_or("legend,axes,box,scale,title".into())
        .parse()
        .unwrap();
    overlay::draw(&mut px, w, h, &all, &info);
    eprintln!("overlay ms {:.2}", t.elapsed().as_secs_f64() * 1e3);
    image::RgbImage::from_raw(w, h, px)
        .unwrap()
        .save(out)
        .unwrap();
}
