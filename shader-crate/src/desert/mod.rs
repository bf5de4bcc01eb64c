//! Desert scenes (the survey's section 5): the sand automaton that forms
//! dunes and wind ripples (`sand`). The terrain it shapes is drawn as the
//! scene's geometry (triangles through the BVH).

pub mod sand;
