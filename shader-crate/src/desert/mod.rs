//! Desert scenes (the survey's section 5): the sand automaton that forms
//! dunes and wind ripples (`sand`), and the ripples' bump textures by
//! level of detail (`ripples`). The terrain it shapes is drawn as the
//! scene's geometry (triangles through the BVH).

pub mod ripples;
pub mod sand;
