//! The forms of a convolution's product beyond the host's algorithms: the few-output product
//! (host and GPU) and the GPU's matrix product, whether a convolution takes it and how.
//!
//! Design decision: the GPU's product (`crate::gpu::matmul_conv`) has sub-forms, the column
//! matrix gathered or built from shifted windows, the product before the shift for few outputs,
//! the bias issued on the product's shape so that burn's fusion takes it into the product's
//! epilogue. Each is a choice from the shapes and the settings' routes, so it is made here, with
//! the host's choices, and the GPU code carries out the [`GpuConvForm`] it is given.

use burn::tensor::ops::ConvOptions;

use crate::algorithm::{GpuColumns, GpuConvForm};
use crate::settings::{GpuRoute, Settings};

/// Most output channels for the few-output kernel, on the host and on the GPU (with a 3x3
/// kernel its product has 9·O rows).
const FEW_OUTPUTS_MAX: usize = 4;

/// Fewest input channels for which the few-output kernel pays: below, the column matrix is small.
const FEW_OUTPUTS_MIN_CHANNELS: usize = 32;

/// Whether a convolution with `o` outputs from `c` inputs takes the product before the shift
/// (the host's few-output kernel, the GPU's product first): stride 1, groups 1, at most
/// [`FEW_OUTPUTS_MAX`] outputs from at least [`FEW_OUTPUTS_MIN_CHANNELS`] inputs.
pub(super) fn few_outputs(options: &ConvOptions<2>, o: usize, c: usize) -> bool {
    options.stride == [1, 1] && options.groups == 1 && o <= FEW_OUTPUTS_MAX && c >= FEW_OUTPUTS_MIN_CHANNELS
}

/// Whether a convolution with `options` and a `kh x kw` kernel takes the GPU's matrix product:
/// groups 1, and either stride 1 with a kernel larger than 1x1, or, with the gathered columns,
/// any stride ([`GpuRoute::StridedProducts`]), or an unpadded 1x1 at stride 1 when the
/// element-wise work after it joins the product's kernel ([`GpuRoute::FusedEpilogue`]; burn runs
/// those as a product already, with the bias in a kernel of its own).
pub(super) fn suits_product(options: &ConvOptions<2>, kernel: [usize; 2], settings: &Settings) -> bool {
    let strided =
        settings.route_enabled(GpuRoute::GatheredColumns) && settings.route_enabled(GpuRoute::StridedProducts);
    let pointwise = kernel == [1, 1] && options.stride == [1, 1] && options.padding == [(0, 0), (0, 0)];
    options.groups == 1
        && if options.stride == [1, 1] {
            kernel != [1, 1] || (settings.route_enabled(GpuRoute::FusedEpilogue) && pointwise)
        } else {
            strided
        }
}

/// The GPU's form of a convolution of an `x_dims = [N, C, H, W]` input with a
/// `w_dims = [O, C, kh, kw]` weight, `None` where it keeps burn's convolution
/// ([`suits_product`]): the columns gathered unless the settings name `stock-route=im2col`; the
/// product first where [`few_outputs`] suits (with gathered columns, whose indices it reuses)
/// unless they name `few-outputs`; the fused epilogue unless `epilogue`.
pub(crate) fn gpu_conv_form(
    x_dims: [usize; 4],
    w_dims: [usize; 4],
    options: &ConvOptions<2>,
    settings: &Settings,
) -> Option<GpuConvForm> {
    let [_, c, _, _] = x_dims;
    let [o, _, kh, kw] = w_dims;
    if !suits_product(options, [kh, kw], settings) {
        return None;
    }
    let gathered = settings.route_enabled(GpuRoute::GatheredColumns);
    Some(GpuConvForm {
        columns: if gathered { GpuColumns::Gathered } else { GpuColumns::Windows },
        product_first: gathered && few_outputs(options, o, c) && settings.route_enabled(GpuRoute::FewOutputs),
        fused_epilogue: settings.route_enabled(GpuRoute::FusedEpilogue),
    })
}

/// The form of the ConvGRU step's two convolutions over one gathering of their shared input's
/// columns (`crate::gpu::matmul_conv::SharedColumns`): where the gates' convolution
/// (`gates`, a `kernel`) takes the GPU's product and the columns are gathered; `None` keeps two
/// convolutions of their own.
pub(super) fn shared_columns_form(
    gates: &ConvOptions<2>,
    kernel: [usize; 2],
    settings: &Settings,
) -> Option<GpuConvForm> {
    (settings.route_enabled(GpuRoute::GatheredColumns) && suits_product(gates, kernel, settings)).then(|| GpuConvForm {
        columns: GpuColumns::Gathered,
        product_first: false,
        fused_epilogue: settings.route_enabled(GpuRoute::FusedEpilogue),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(stride: usize, padding: usize) -> ConvOptions<2> {
        ConvOptions::new([stride; 2], [padding; 2], [1; 2], 1)
    }

    /// The GPU's product takes stride-1 kernels larger than 1x1, strided ones through the
    /// gathered columns, and unpadded 1x1s only with the fused epilogue.
    #[test]
    fn gpu_products_take_their_shapes() {
        let s = Settings::default();
        assert!(suits_product(&options(1, 1), [3, 3], &s));
        assert!(suits_product(&options(2, 1), [3, 3], &s));
        assert!(suits_product(&options(1, 0), [1, 1], &s));
        assert!(!suits_product(&options(1, 1), [1, 1], &s), "a padded 1x1");
        let off: Settings = "stock-route=strided,stock-route=epilogue".parse().expect("settings");
        assert!(!suits_product(&options(2, 1), [3, 3], &off));
        assert!(!suits_product(&options(1, 0), [1, 1], &off));
    }

    /// Only few outputs from many inputs at stride 1 take the product first.
    #[test]
    fn few_outputs_from_many_inputs_suit() {
        let same = options(1, 1);
        assert!(few_outputs(&same, 2, 256) && few_outputs(&same, 4, 32));
        assert!(!few_outputs(&same, 5, 256) && !few_outputs(&same, 2, 31));
        assert!(!few_outputs(&options(2, 1), 2, 256));
        assert!(!few_outputs(&ConvOptions::new([1; 2], [1; 2], [1; 2], 2), 2, 256), "grouped");
    }

    /// The forms of representative layers of the default model, with the default settings and
    /// with each route of a sub-form turned off.
    #[test]
    fn gpu_forms_of_representative_layers() {
        let form =
            |columns, product_first, fused_epilogue| Some(GpuConvForm { columns, product_first, fused_epilogue });
        let (gathered, windows) = (GpuColumns::Gathered, GpuColumns::Windows);
        let s = Settings::default();
        let gru = ([1, 384, 96, 112], [256, 384, 3, 3], options(1, 1));
        let flow_head = ([1, 256, 96, 112], [2, 256, 3, 3], options(1, 1));
        let small_input = ([1, 16, 96, 112], [2, 16, 3, 3], options(1, 1));
        let stem = ([1, 3, 384, 448], [64, 3, 7, 7], options(2, 3));
        let grouped = ConvOptions::new([1, 1], [1, 1], [1, 1], 2);
        let table = [
            ("GRU 384->256", gru.clone(), &s, form(gathered, false, true)),
            ("flow head 256->2", flow_head.clone(), &s, form(gathered, true, true)),
            ("2 outputs from 16 inputs", small_input, &s, form(gathered, false, true)),
            ("stem 7x7/2", stem.clone(), &s, form(gathered, false, true)),
            ("grouped", ([1, 32, 8, 8], [32, 16, 3, 3], grouped), &s, None),
        ];
        for (name, (x, w, o), settings, want) in table {
            assert_eq!(gpu_conv_form(x, w, &o, settings), want, "{name}");
        }
        let (x, w, o) = flow_head;
        let no_few: Settings = "stock-route=few-outputs".parse().expect("settings");
        assert_eq!(gpu_conv_form(x, w, &o, &no_few), form(gathered, false, true));
        let windows_only: Settings = "stock-route=im2col".parse().expect("settings");
        assert_eq!(gpu_conv_form(x, w, &o, &windows_only), form(windows, false, true), "no product first on windows");
        let (x, w, o) = stem;
        assert_eq!(gpu_conv_form(x, w, &o, &windows_only), None, "strides need the gathered columns");
        let no_epilogue: Settings = "stock-route=epilogue".parse().expect("settings");
        let (x, w, o) = gru;
        assert_eq!(gpu_conv_form(x, w, &o, &no_epilogue), form(gathered, false, false));
        assert_eq!(shared_columns_form(&o, [3, 3], &s), form(gathered, false, true));
        assert_eq!(shared_columns_form(&o, [3, 3], &windows_only), None);
    }
}
