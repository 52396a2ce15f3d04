//! Arrow hand-over: a kernel `Table` becomes a struct array exported through the Arrow C data
//! interface as PyCapsules (`__arrow_c_schema__`, `__arrow_c_array__`), which pyarrow and
//! polars import without copying the column buffers.

use arrow_array::{Array, ArrayRef, Float64Array, Int64Array, StructArray};
use arrow_schema::{DataType, Field, Fields};
use granflow::table::{Column, Table};
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyTuple};
use std::collections::HashMap;
use std::sync::Arc;

/// One Arrow record batch (column names follow docs/columns.md; units in field metadata).
#[pyclass(module = "granflow._core", frozen)]
pub struct ArrowBatch {
    array: StructArray,
    metadata: HashMap<String, String>,
    pub name: String,
}

#[repr(transparent)]
struct SendSchema(arrow_schema::ffi::FFI_ArrowSchema);
unsafe impl Send for SendSchema {}
#[repr(transparent)]
struct SendArray(arrow_array::ffi::FFI_ArrowArray);
unsafe impl Send for SendArray {}

impl ArrowBatch {
    /// Take a table's columns over (their buffers become the Arrow arrays' without a copy).
    pub fn from_table(name: &str, t: Table) -> Self {
        let mut fields = Vec::with_capacity(t.columns.len());
        let mut arrays: Vec<ArrayRef> = Vec::with_capacity(t.columns.len());
        for (cname, unit, col) in t.columns {
            let md: HashMap<String, String> = [("unit".to_string(), unit)].into();
            match col {
                Column::F64(v) => {
                    fields.push(Field::new(cname, DataType::Float64, false).with_metadata(md));
                    arrays.push(Arc::new(Float64Array::from(v)));
                }
                Column::I64(v) => {
                    fields.push(Field::new(cname, DataType::Int64, false).with_metadata(md));
                    arrays.push(Arc::new(Int64Array::from(v)));
                }
            }
        }
        let array = if fields.is_empty() {
            StructArray::new_empty_fields(0, None)
        } else {
            StructArray::new(Fields::from(fields), arrays, None)
        };
        ArrowBatch {
            array,
            metadata: t.metadata.into_iter().collect(),
            name: name.to_string(),
        }
    }

    fn field(&self) -> Field {
        Field::new("", self.array.data_type().clone(), false).with_metadata(self.metadata.clone())
    }
}

#[pymethods]
impl ArrowBatch {
    /// Number of rows.
    fn __len__(&self) -> usize {
        self.array.len()
    }
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }
    fn __arrow_c_schema__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyCapsule>> {
        let schema = arrow_schema::ffi::FFI_ArrowSchema::try_from(self.field())
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
        PyCapsule::new_with_value(py, SendSchema(schema), c"arrow_schema")
    }
    #[pyo3(signature = (requested_schema=None))]
    fn __arrow_c_array__<'py>(
        &self,
        py: Python<'py>,
        requested_schema: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let _ = requested_schema; // we export our own schema; callers may cast
        let schema = self.__arrow_c_schema__(py)?;
        let data = arrow_array::Array::to_data(&self.array);
        let arr = arrow_array::ffi::FFI_ArrowArray::new(&data);
        let arr = PyCapsule::new_with_value(py, SendArray(arr), c"arrow_array")?;
        PyTuple::new(py, [schema.into_any(), arr.into_any()])
    }
}
