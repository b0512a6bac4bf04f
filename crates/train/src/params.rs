//! Parameters by module path: listing them, and giving a rebuilt model the identities of a saved one.
//!
//! burn's optimiser keys its per-parameter state by [`ParamId`], a random identity created with
//! the parameter, and safetensors files carry no identity. A checkpoint therefore stores the map
//! from module path to id, and resuming re-labels the freshly built model's parameters with the
//! saved ids ([`assign_param_ids`]) so the saved optimiser state attaches to the same tensors.
//! burn also draws a parameter's initial value lazily, at its first use; [`materialize`] draws
//! them all at once.

use std::collections::BTreeMap;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::tensor::{Bool, Int, Tensor};

/// Tracks the dotted module path during a traversal.
#[derive(Default)]
pub(crate) struct PathStack(Vec<String>);

impl PathStack {
    pub(crate) fn enter(&mut self, name: &str) {
        self.0.push(name.to_string());
    }
    pub(crate) fn exit(&mut self) {
        self.0.pop();
    }
    pub(crate) fn current(&self) -> String {
        self.0.join(".")
    }
}

struct Lister {
    path: PathStack,
    found: Vec<(String, ParamId, bool)>,
}

impl ModuleVisitor for Lister {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.enter(name);
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.exit();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.found.push((self.path.current(), param.id, param.val().is_require_grad()));
    }
}

/// Every float parameter of `module`: `(path, id, requires_grad)` in traversal order.
pub fn float_params<M: Module>(module: &M) -> Vec<(String, ParamId, bool)> {
    let mut lister = Lister { path: PathStack::default(), found: Vec::new() };
    module.visit(&mut lister);
    lister.found
}

/// The map from module path to parameter id (stored in checkpoints).
pub fn param_ids<M: Module>(module: &M) -> BTreeMap<String, u64> {
    float_params(module).into_iter().map(|(path, id, _)| (path, id.val())).collect()
}

struct IdAssigner<'a> {
    path: PathStack,
    ids: &'a BTreeMap<String, u64>,
    missing: Vec<String>,
}

impl ModuleMapper for IdAssigner<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.enter(name);
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.exit();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let path = self.path.current();
        match self.ids.get(&path) {
            Some(&id) => {
                let (_, value, mapper) = param.consume();
                Param::from_mapped_value(ParamId::from(id), value, mapper)
            }
            None => {
                self.missing.push(path);
                param
            }
        }
    }
}

/// Gives each float parameter of `module` the id saved for its path; returns the module and the
/// paths that had no saved id (they keep their own).
pub fn assign_param_ids<M: Module>(module: M, ids: &BTreeMap<String, u64>) -> (M, Vec<String>) {
    let mut assigner = IdAssigner { path: PathStack::default(), ids, missing: Vec::new() };
    let module = module.map(&mut assigner);
    (module, assigner.missing)
}

struct Materializer;

impl ModuleVisitor for Materializer {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let _ = param.val();
    }
    fn visit_int<const D: usize>(&mut self, param: &Param<Tensor<D, Int>>) {
        let _ = param.val();
    }
    fn visit_bool<const D: usize>(&mut self, param: &Param<Tensor<D, Bool>>) {
        let _ = param.val();
    }
}

/// Draws the initial value of every lazily initialised parameter of `module` now, in module
/// order (the order a first traversal would draw them in).
pub fn materialize<M: Module>(module: &M) {
    module.visit(&mut Materializer);
}
