"""Materials of the engine models' kernel tests (keyword arguments of
:class:`brdffit.export.gltf_brdf.GLTFBRDF` and the engine models built like it): a metal, a
dielectric with ``KHR_materials_specular`` and a coated mix of both."""

ENGINE_TEST_MATERIALS = [
    dict(base_color=[0.9, 0.6, 0.3], metallic=1.0, roughness=0.4),
    dict(base_color=[0.2, 0.5, 0.0], metallic=0.0, roughness=0.3, specular_factor=0.7,
         specular_color=[1.0, 0.8, 0.5], ior=2.2),
    dict(base_color=[0.6, 0.1, 0.3], metallic=0.3, roughness=0.5, clearcoat=0.5,
         clearcoat_roughness=0.2),
]
