<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>
<qgis version="3.28.0-Firenze" styleCategories="Symbology">
  <pipe-data-defined-properties>
    <Option type="Map">
      <Option value="" type="QString" name="name"/>
      <Option name="properties"/>
      <Option value="collection" type="QString" name="type"/>
    </Option>
  </pipe-data-defined-properties>
  <pipe>
    <provider>
      <resampling enabled="false" maxOversampling="2" zoomedOutResamplingMethod="nearestNeighbour" zoomedInResamplingMethod="nearestNeighbour"/>
    </provider>
    <rasterrenderer opacity="1" band="1" alphaBand="-1" nodataColor="" classificationMin="-1" classificationMax="1" type="singlebandpseudocolor">
      <minMaxOrigin>
        <limits>None</limits>
        <extent>WholeRaster</extent>
        <statAccuracy>Estimated</statAccuracy>
        <cumulativeCutLower>0.02</cumulativeCutLower>
        <cumulativeCutUpper>0.98</cumulativeCutUpper>
        <stdDevFactor>2</stdDevFactor>
      </minMaxOrigin>
      <rastershader>
        <colorrampshader maximumValue="1" minimumValue="-1" colorRampType="INTERPOLATED" classificationMode="1" labelPrecision="2" clip="0">
          <colorramp type="gradient" name="[source]">
            <Option type="Map">
              <Option value="202,0,32,255,rgb:0.792156862745098,0,0.12549019607843137,1" type="QString" name="color1"/>
              <Option value="5,113,176,255,rgb:0.0196078431372549,0.44313725490196076,0.69019607843137254,1" type="QString" name="color2"/>
              <Option value="ccw" type="QString" name="direction"/>
              <Option value="0" type="QString" name="discrete"/>
              <Option value="gradient" type="QString" name="rampType"/>
              <Option value="rgb" type="QString" name="spec"/>
              <Option value="0.25;244,165,130,255,rgb:0.95686274509803926,0.6470588235294118,0.50980392156862742,1;rgb;ccw:0.5;247,247,247,255,rgb:0.96862745098039216,0.96862745098039216,0.96862745098039216,1;rgb;ccw:0.75;146,197,222,255,rgb:0.5725490196078431,0.77254901960784317,0.87058823529411766,1;rgb;ccw" type="QString" name="stops"/>
            </Option>
          </colorramp>
          <item color="#ca0020" alpha="255" value="-1" label="-1"/>
          <item color="#f4a582" alpha="255" value="-0.5" label="-0.5"/>
          <item color="#f7f7f7" alpha="255" value="0" label="0"/>
          <item color="#92c5de" alpha="255" value="0.5" label="0.5"/>
          <item color="#0571b0" alpha="255" value="1" label="1"/>
          <rampLegendSettings minimumLabel="" maximumLabel="" orientation="2" useContinuousLegend="1" direction="0" suffix=" m" prefix="">
            <numericFormat id="basic">
              <Option type="Map">
                <Option type="invalid" name="decimal_separator"/>
                <Option value="2" type="int" name="decimals"/>
                <Option value="0" type="int" name="rounding_type"/>
                <Option value="false" type="bool" name="show_plus"/>
                <Option value="true" type="bool" name="show_thousand_separator"/>
                <Option value="false" type="bool" name="show_trailing_zeros"/>
                <Option type="invalid" name="thousand_separator"/>
              </Option>
            </numericFormat>
          </rampLegendSettings>
        </colorrampshader>
      </rastershader>
    </rasterrenderer>
    <brightnesscontrast brightness="0" gamma="1" contrast="0"/>
    <huesaturation grayscaleMode="0" colorizeBlue="128" colorizeStrength="100" invertColors="0" saturation="0" colorizeOn="0" colorizeRed="255" colorizeGreen="128"/>
    <rasterresampler maxOversampling="2"/>
    <resamplingStage>resamplingFilter</resamplingStage>
  </pipe>
  <blendMode>0</blendMode>
</qgis>
