//! Vertex attributes as floats, whatever their component type. Core glTF stores POSITION and
//! NORMAL as f32 and TEXCOORD_0 as f32 or normalised u8/u16; KHR_mesh_quantization (what
//! gltfpack writes by default) allows integers too: positions as i8/u8/i16/u16, normalised or
//! not (the node's transform usually scales them back), normals as normalised i8/i16, texture
//! coordinates as i8/u8/i16/u16, normalised or not. The `gltf` crate reads positions and
//! normals as f32 only, so the component type is dispatched here on the crate's typed
//! accessor iterator, which handles strides and sparse accessors.

use ::gltf::accessor::{DataType, Item, Iter};
use ::gltf::{Accessor, Buffer};

/// Floats from one stored component: a normalised integer maps onto [0, 1] (unsigned) or
/// [−1, 1] (signed, the most negative value clamped to −1), as glTF 2.0 §3.11 says; any
/// other component keeps its value.
trait Component: Item + Copy + 'static {
    fn float(self, normalized: bool) -> f32;
}

impl Component for f32 {
    fn float(self, _: bool) -> f32 {
        self
    }
}

macro_rules! integer_component {
    ($t:ty, $signed:expr) => {
        impl Component for $t {
            fn float(self, normalized: bool) -> f32 {
                let value = self as f32;
                match (normalized, $signed) {
                    (false, _) => value,
                    (true, true) => (value / <$t>::MAX as f32).max(-1.0),
                    (true, false) => value / <$t>::MAX as f32,
                }
            }
        }
    };
}
integer_component!(i8, true);
integer_component!(u8, false);
integer_component!(i16, true);
integer_component!(u16, false);

/// Elements of `N` floats.
pub(super) type Floats<'s, const N: usize> = Box<dyn Iterator<Item = [f32; N]> + 's>;

fn converted<'a, 's, C: Component, const N: usize>(
    accessor: Accessor<'a>,
    data: impl Clone + Fn(Buffer<'a>) -> Option<&'s [u8]>,
) -> Option<Floats<'s, N>>
where
    [C; N]: Item,
{
    let normalized = accessor.normalized();
    let elements = Iter::<[C; N]>::new(accessor, data)?;
    Some(Box::new(elements.map(move |e| e.map(|c| c.float(normalized)))))
}

/// The elements of `accessor` (of `N` components, checked by the caller) as floats; `None`
/// where its data cannot be read or its type is u32.
pub(super) fn read<'a, 's, const N: usize>(
    accessor: Accessor<'a>,
    data: impl Clone + Fn(Buffer<'a>) -> Option<&'s [u8]>,
) -> Option<Floats<'s, N>>
where
    [f32; N]: Item,
    [i8; N]: Item,
    [u8; N]: Item,
    [i16; N]: Item,
    [u16; N]: Item,
{
    match accessor.data_type() {
        DataType::F32 => converted::<f32, N>(accessor, data),
        DataType::I8 => converted::<i8, N>(accessor, data),
        DataType::U8 => converted::<u8, N>(accessor, data),
        DataType::I16 => converted::<i16, N>(accessor, data),
        DataType::U16 => converted::<u16, N>(accessor, data),
        DataType::U32 => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_integers_map_onto_the_unit_range_and_others_keep_their_value() {
        assert_eq!(127i8.float(true), 1.0);
        assert_eq!((-128i8).float(true), -1.0);
        assert_eq!((-127i8).float(true), -1.0);
        assert_eq!(255u8.float(true), 1.0);
        assert_eq!(32767i16.float(true), 1.0);
        assert_eq!(65535u16.float(true), 1.0);
        assert_eq!(0u16.float(true), 0.0);
        assert_eq!(16383u16.float(false), 16383.0);
        assert_eq!((-5i8).float(false), -5.0);
        assert_eq!(0.25f32.float(true), 0.25);
    }
}
