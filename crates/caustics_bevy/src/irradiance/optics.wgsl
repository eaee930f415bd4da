// Reflection, refraction and Fresnel transmittance, the WGSL twins of
// `caustics_core::optics`: what the techniques that bend light on the GPU share.

#define_import_path bevy_caustics::optics

// `optics::reflect`.
fn reflect_about(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - 2.0 * dot(d, n) * n;
}

// `optics::refract`: xyz the transmitted direction, w 0 under total internal reflection.
fn refract_through(incident: vec3<f32>, normal: vec3<f32>, eta: f32) -> vec4<f32> {
    if eta == 1.0 {
        return vec4(incident, 1.0);
    }
    var n = normal;
    var cos_i = -dot(incident, n);
    if cos_i < 0.0 {
        n = -n;
        cos_i = -cos_i;
    }
    cos_i = min(cos_i, 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return vec4(0.0);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let t = eta * incident + (eta * cos_i - cos_t) * n;
    let len = length(t);
    if len > 0.0 {
        return vec4(t / len, 1.0);
    }
    return vec4(incident, 1.0);
}

// `optics::fresnel_transmittance`.
fn fresnel_transmittance(cos_incident: f32, eta: f32) -> f32 {
    if eta == 1.0 {
        return 1.0;
    }
    let cos_i = min(abs(cos_incident), 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 0.0;
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r = 0.5 * (rs * rs + rp * rp);
    if r != r || r > 1.0 {
        return 0.0;
    }
    return 1.0 - max(r, 0.0);
}
